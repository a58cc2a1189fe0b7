// Hostile input to `magcomp navigate` on MagNav.jl's simple example: maps that are not maps
// (off the track, masked, on projected axes, stretched, huge, 25 GB declared), flights with NaN,
// poles, duplicated stamps and gaps, settings that overflow. Each is a one-line error, or a
// finite result that says how many measurements it used and counts what it could not use.
#include <gtest/gtest.h>
#include <hdf5.h>

#include <cmath>
#include <fstream>
#include <functional>
#include <limits>
#include <map>
#include <nlohmann/json.hpp>

#include "hostile_util.h"
#include "magcomp/core/io/h5_array.h"
#include "magcomp/core/nav/anomaly_map.h"

namespace magcomp {
namespace {

using test::expect_refusal;

const double kNaN = std::numeric_limits<double>::quiet_NaN();

std::string example(const std::string& file) {
  return test::reference_dir() + "/magnav_nav/" + file;
}

const std::string& dir() {
  static const std::string d = test::temp_dir("hostile_nav");
  return d;
}

// The example's map with its arrays changed by `edit` (MagNav.jl's layout: map[j][i] holds
// latitude i, longitude j of the square grid).
std::string map_with(const std::string& name,
                     const std::function<void(std::map<std::string, H5Array>*)>& edit) {
  std::map<std::string, H5Array> a;
  for (const char* k : {"map", "xx", "yy", "alt", "mask"})
    a[k] = read_h5_array(example("simple_map.h5"), k);
  edit(&a);
  std::vector<std::pair<std::string, H5Array>> out(a.begin(), a.end());
  const std::string p = dir() + "/" + name;
  write_h5_arrays(p, out);
  return p;
}

// The example's flight with column `field` changed by `edit`.
std::string flight_with(const std::string& name, const std::string& field,
                        const std::function<void(Eigen::VectorXd*)>& edit) {
  FlightData f = read_flight_h5(example("simple_xyz.h5"));
  Eigen::VectorXd v = f.column(field);
  edit(&v);
  f.set(field, v);
  const std::string p = dir() + "/" + name;
  write_flight_h5(f, p);
  return p;
}

// Runs navigate; expects success, no NaN printed, and returns the JSON.
nlohmann::json navigate_ok(const std::string& args, std::string* printed = nullptr) {
  const std::string json = dir() + "/nav.json";
  std::string out;
  EXPECT_EQ(test::run(test::cli() + " navigate " + args + " --json " + json, &out), 0)
      << args << "\n"
      << out;
  EXPECT_FALSE(test::prints_nan(out)) << out;
  if (printed) *printed = out;
  return nlohmann::json::parse(std::ifstream(json));
}

TEST(HostileNavigation, AMapThatNeverMeetsTheTrackIsAnErrorNotAScore) {
  const std::string data = " --data " + example("simple_xyz.h5") + " --anomaly mag_1_c";
  // 10 degrees east of the track.
  expect_refusal("navigate" + data + " --map " +
                     map_with("away.h5",
                              [](auto* a) {
                                for (double& v : (*a)["xx"].values) v += 10;
                              }),
                 {"no measurement of mag_1_c was used in 100 steps", "100 off the map", "away.h5",
                  "lon -85.8700"});
  // Every cell masked; every cell NaN.
  expect_refusal("navigate" + data + " --map " +
                     map_with("masked.h5",
                              [](auto* a) {
                                for (double& v : (*a)["mask"].values) v = 0;
                              }),
                 {"masked.h5", "field 'map' has no valid cell"});
  expect_refusal("navigate" + data + " --map " +
                     map_with("all_nan.h5",
                              [](auto* a) {
                                for (double& v : (*a)["map"].values) v = kNaN;
                              }),
                 {"all_nan.h5", "no valid cell"});
  // Axes in metres (a projected grid).
  expect_refusal("navigate" + data + " --map " +
                     map_with("metres.h5",
                              [](auto* a) {
                                for (size_t k = 0; k < 100; ++k) {
                                  (*a)["xx"].values[k] = 5e5 + 1000.0 * static_cast<double>(k);
                                  (*a)["yy"].values[k] = 4.3e6 + 1000.0 * static_cast<double>(k);
                                }
                              }),
                 {"metres.h5", "field 'yy'", "not a latitude in degrees or radians"});
}

TEST(HostileNavigation, MapsAreValidatedOnReading) {
  const std::string data = " --data " + example("simple_xyz.h5") + " --anomaly mag_1_c";
  expect_refusal("navigate" + data + " --map " +
                     map_with("stretched.h5",
                              [](auto* a) {
                                (*a)["xx"].values[50] += 0.004;  // 0.4 of a step
                              }),
                 {"stretched.h5", "field 'xx' is not uniform", "value 50"});
  expect_refusal("navigate" + data + " --map " +
                     map_with("inf_axis.h5",
                              [](auto* a) {
                                (*a)["yy"].values[99] = std::numeric_limits<double>::infinity();
                              }),
                 {"inf_axis.h5", "field 'yy' holds a non-finite value at index 99"});
  expect_refusal("navigate" + data + " --map " +
                     map_with("scaled.h5",
                              [](auto* a) {
                                for (double& v : (*a)["map"].values) v *= 1e300;
                              }),
                 {"scaled.h5", "field 'map' cell", "beyond any magnetic field"});
  // A 40000 x 40000 grid declared in a small file: refused before 12.8 GB are asked for.
  const std::string big = dir() + "/big.h5";
  {
    const std::string src = map_with("big_base.h5", [](auto*) {});
    std::ofstream(big, std::ios::binary) << test::slurp(src);
    const hid_t file = H5Fopen(big.c_str(), H5F_ACC_RDWR, H5P_DEFAULT);
    ASSERT_GE(file, 0);
    H5Ldelete(file, "map", H5P_DEFAULT);
    hsize_t dims[2] = {40000, 40000}, chunk[2] = {100, 100};
    const hid_t space = H5Screate_simple(2, dims, nullptr);
    const hid_t plist = H5Pcreate(H5P_DATASET_CREATE);
    H5Pset_chunk(plist, 2, chunk);
    const hid_t ds =
        H5Dcreate2(file, "map", H5T_IEEE_F64LE, space, H5P_DEFAULT, plist, H5P_DEFAULT);
    ASSERT_GE(ds, 0);
    H5Dclose(ds);
    H5Pclose(plist);
    H5Sclose(space);
    H5Fclose(file);
  }
  expect_refusal("navigate" + data + " --map " + big,
                 {"big.h5", "dataset 'map' declares 1600000000 values"});
}

// A map whose dataset's integer datatype is corrupt (found by fuzzing map_h5): libhdf5's
// conversion to doubles faults (SIGBUS) on it; the probe process reads the values first, so the
// command refuses the file in one line instead of dying.
TEST(HostileNavigation, AMapThatCrashesTheHdf5LibraryIsRefusedInOneLine) {
  expect_refusal("navigate --data " + example("simple_xyz.h5") + " --anomaly mag_1_c --map " +
                     test::source_dir() + "/test/cli/data/map_corrupt_datatype.h5",
                 {"map_corrupt_datatype.h5", "corrupt HDF5 file"});
}

// The map's own error (R's map term with --model-variance): read from the file's
// `error_sigma_nT` when it has one, a stated 0.3 nT otherwise; a negative, infinite or
// several-valued error is refused naming the file and the field.
TEST(HostileNavigation, AMapsOwnErrorIsReadFromItsFileAndValidated) {
  EXPECT_EQ(nav::read_anomaly_map(example("simple_map.h5")).error_sigma_nT, 0.3);
  const auto with_error = [](const std::string& name, std::vector<double> e) {
    return map_with(name, [&](auto* a) { (*a)["error_sigma_nT"] = H5Array{{e.size()}, e}; });
  };
  EXPECT_EQ(nav::read_anomaly_map(with_error("sigma_2.h5", {2.0})).error_sigma_nT, 2.0);
  const std::string data = " --data " + example("simple_xyz.h5") + " --anomaly mag_1_c --map ";
  expect_refusal("navigate" + data + with_error("sigma_neg.h5", {-1.0}),
                 {"sigma_neg.h5", "field 'error_sigma_nT'"});
  expect_refusal(
      "navigate" + data + with_error("sigma_inf.h5", {std::numeric_limits<double>::infinity()}),
      {"sigma_inf.h5", "field 'error_sigma_nT'"});
  expect_refusal("navigate" + data + with_error("sigma_two.h5", {0.3, 0.4}),
                 {"sigma_two.h5", "field 'error_sigma_nT'"});
}

TEST(HostileNavigation, NanMapCellsUnderTheTrackAreMaskedNotInterpolated) {
  // The true position at the example's sample 50, and a 3 x 3 block of NaN cells about it.
  const FlightData f = read_flight_h5(example("simple_xyz.h5"));
  const double lat = f.column("lat")[50], lon = f.column("lon")[50];
  const std::string map = map_with("nan_cells.h5", [&](auto* a) {
    const auto& yy = (*a)["yy"].values;
    const auto& xx = (*a)["xx"].values;
    const auto i = static_cast<long>(std::floor((lat - yy[0]) / (yy[1] - yy[0])));
    const auto j = static_cast<long>(std::floor((lon - xx[0]) / (xx[1] - xx[0])));
    for (long di = -1; di <= 1; ++di)
      for (long dj = -1; dj <= 1; ++dj)
        (*a)["map"].values[static_cast<size_t>((j + dj) * 100 + (i + di))] = kNaN;
  });
  std::string out;
  const nlohmann::json j = navigate_ok(
      "--data " + example("simple_xyz.h5") + " --map " + map + " --anomaly mag_1_c", &out);
  const long used = j["samples"]["measurements_used"];
  EXPECT_GT(used, 50);
  EXPECT_LT(used, 100);  // the steps over the NaN cells went without their measurement
  EXPECT_EQ(j["faults"]["off_map"].get<long>(), 100 - used);
  EXPECT_LT(j["drms_filter_m"].get<double>(), 10.0);
  EXPECT_NE(out.find("measurements off the map"), std::string::npos) << out;
}

TEST(HostileNavigation, BadRowsAreLeftOutAndCountedAsOnline) {
  const std::string map = " --map " + example("simple_map.h5") + " --anomaly mag_1_c";
  // One NaN in each INS field: that INS sample is refused (a gap), the rest navigates.
  for (const char* field : {"ins_lat", "ins_lon", "ins_alt", "ins_roll", "ins_pitch", "ins_yaw"}) {
    const nlohmann::json j = navigate_ok(
        "--data " +
        flight_with(std::string("nan_") + field + ".h5", field, [](auto* v) { (*v)[50] = kNaN; }) +
        map);
    EXPECT_EQ(j["faults"]["ins_refused"].get<long>(), 1) << field;
    EXPECT_EQ(j["samples"]["steps"].get<long>(), 99) << field;
    EXPECT_NEAR(j["drms_filter_m"].get<double>(), 2.0, 0.2) << field;
  }
  // The INS at a pole and 1e300 m up: refused the same way.
  nlohmann::json j = navigate_ok(
      "--data " + flight_with("pole.h5", "ins_lat", [](auto* v) { (*v)[30] = 90.0; }) + map);
  EXPECT_EQ(j["faults"]["ins_refused"].get<long>(), 1);
  j = navigate_ok("--data " + flight_with("high.h5", "ins_alt", [](auto* v) { (*v)[30] = 1e300; }) +
                  map);
  EXPECT_EQ(j["faults"]["ins_refused"].get<long>(), 1);
  // A NaN in the truth: that sample is not scored; the filter runs on all 100.
  for (const char* field : {"lat", "lon", "alt"}) {
    j = navigate_ok("--data " +
                    flight_with(std::string("truth_nan_") + field + ".h5", field,
                                [](auto* v) { (*v)[50] = kNaN; }) +
                    map);
    EXPECT_EQ(j["faults"]["truth_refused"].get<long>(), 1) << field;
    EXPECT_EQ(j["samples"]["scored"].get<long>(), 99) << field;
    EXPECT_EQ(j["samples"]["steps"].get<long>(), 100) << field;
  }
  // A duplicated stamp: the second is dropped like a late message (and its gap counted).
  j = navigate_ok("--data " + flight_with("dup_tt.h5", "tt", [](auto* v) { (*v)[51] = (*v)[50]; }) +
                  map);
  EXPECT_EQ(j["faults"]["out_of_order_or_duplicate"].get<long>(), 2);  // its INS and measurement
  EXPECT_EQ(j["faults"]["ins_gaps"].get<long>(), 1);
  // A 1,000 s gap: propagated across (the bound grows with it), counted, never one plain step.
  j = navigate_ok("--data " +
                  flight_with("gap.h5", "tt", [](auto* v) { v->tail(50).array() += 1000.0; }) +
                  map);
  EXPECT_EQ(j["faults"]["ins_gaps"].get<long>(), 1);
  EXPECT_GT(j["drms_crlb_m"].get<double>(), 10.0);  // 6.6 m without the gap
}

TEST(HostileNavigation, SettingsAndMeasurementsThatOverflowAreRefused) {
  const std::string args = "navigate --data " + example("simple_xyz.h5") + " --map " +
                           example("simple_map.h5") + " --anomaly mag_1_c";
  expect_refusal(args + " --fogm-sigma inf", {"--fogm-sigma", "must be in (0, 100000] nT"});
  expect_refusal(args + " --init-pos-sigma 1e308", {"--init-pos-sigma", "(got 1e+308)"});
  expect_refusal(args + " --meas-sigma -1", {"--meas-sigma"});
  expect_refusal(args + " --fogm-tau nan", {"--fogm-tau"});
  // An anomaly scaled by 1e300: every measurement refused, so none used: an error.
  expect_refusal("navigate --data " +
                     flight_with("anomaly_huge.h5", "mag_1_c", [](auto* v) { *v *= 1e300; }) +
                     " --map " + example("simple_map.h5") + " --anomaly mag_1_c",
                 {"no measurement of mag_1_c was used", "100 refused"});
}

TEST(HostileNavigation, AReportWithSamplesWithoutTruthIsWritten) {
  const std::string report = dir() + "/report";
  std::string out;
  ASSERT_EQ(
      test::run(test::cli() + " navigate --data " +
                    flight_with("report_nan.h5", "lat", [](auto* v) { (*v)[10] = kNaN; }) +
                    " --map " + example("simple_map.h5") + " --anomaly mag_1_c --report " + report,
                &out),
      0)
      << out;
  EXPECT_TRUE(test::exists(report + "/index.html")) << out;
  EXPECT_TRUE(test::exists(report + "/tracks.png")) << out;
}

}  // namespace
}  // namespace magcomp
