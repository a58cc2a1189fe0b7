// magcomp navigate through the CLI on MagNav.jl's simple example: the JSON's figures, the
// refusals of bad input in one line.
#include <gtest/gtest.h>

#include <fstream>
#include <nlohmann/json.hpp>

#include "test_util.h"

namespace magcomp {
namespace {

std::string example(const std::string& file) {
  return test::reference_dir() + "/magnav_nav/" + file;
}

TEST(CliNavigate, TheSimpleExampleInMetres) {
  const std::string dir = test::temp_dir("navigate");
  std::string out;
  ASSERT_EQ(
      test::run(test::cli() + " navigate --data " + example("simple_xyz.h5") + " --map " +
                    example("simple_map.h5") + " --anomaly mag_1_c --json " + dir + "/nav.json",
                &out),
      0)
      << out;
  std::printf("%s", out.c_str());
  const nlohmann::json j = nlohmann::json::parse(std::ifstream(dir + "/nav.json"));
  for (const char* k :
       {"drms_filter_m", "drms_ins_m", "drms_crlb_m", "nees_in_95_bounds", "innovation_mean_nT",
        "innovation_std_nT", "nis_mean", "measurement_minus_map_std_nT"})
    ASSERT_TRUE(j.contains(k)) << k;
  // The measurement is the map at the true positions; the filter stays with this INS (2 m)
  // and within 1.5x its bound.
  EXPECT_LT(j["measurement_minus_map_std_nT"].get<double>(), 1e-6);
  EXPECT_LT(j["drms_filter_m"].get<double>(), 1.5 * j["drms_crlb_m"].get<double>());
  EXPECT_LT(j["drms_filter_m"].get<double>(), 1.05 * j["drms_ins_m"].get<double>());
}

TEST(CliNavigate, BadInputIsOneLine) {
  std::string out;
  EXPECT_NE(test::run(test::cli() + " navigate --data " + example("simple_xyz.h5") + " --map " +
                          example("simple_map.h5"),
                      &out),
            0);
  EXPECT_NE(out.find("exactly one of --model and --anomaly"), std::string::npos) << out;
  EXPECT_NE(test::run(test::cli() + " navigate --data " + example("simple_xyz.h5") + " --map " +
                          example("simple_xyz.h5") + " --anomaly mag_1_c",
                      &out),
            0);
  EXPECT_NE(out.find("simple_xyz.h5: dataset 'map' not found"), std::string::npos) << out;
  EXPECT_NE(test::run(test::cli() + " navigate --data " + example("simple_xyz.h5") + " --map " +
                          example("simple_map.h5") + " --anomaly no_such_field",
                      &out),
            0);
  EXPECT_NE(out.find("no_such_field"), std::string::npos) << out;
}

}  // namespace
}  // namespace magcomp
