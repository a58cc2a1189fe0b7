// Hostile input through the command line: every case gives one `error:` line naming the file,
// field or key, a non-zero exit, and leaves every file it was not asked to write as it was.
#include <gtest/gtest.h>
#include <hdf5.h>
#include <sys/stat.h>

#include <fstream>
#include <limits>
#include <sstream>

#include "hostile_util.h"

namespace magcomp {
namespace {

using test::exists;
using test::expect_refusal;
using test::files;
using test::flight_with;
using test::model_with;
using test::slurp;
using test::write;

TEST(HostileInput, AModelWithNoFittableColumnIsRefusedNotACrash) {
  const std::string bp = "{method: bandpass, lines: [1001.02, 1001.04]}";
  for (const char* terms : {"[]", "[bias]", "['lag:0.3']"}) {
    expect_refusal("calibrate --data " + files().flight + " --model " + model_with(terms, bp) +
                       " --out " + files().dir + "/o.yaml",
                   {"fit: the model has no column to fit"});
  }
  expect_refusal("calibrate --data " + files().flight + " --model " + model_with("[]", bp) +
                     " --term lag:0.3 --out " + files().dir + "/o.yaml",
                 {"no column to fit"});
  EXPECT_FALSE(exists(files().dir + "/o.yaml"));
}

TEST(HostileInput, SettingsThatGiveNanAreRefusedAndNothingIsWritten) {
  const std::string out = files().dir + "/nan.yaml";
  expect_refusal(
      "calibrate --data " + files().flight + " --model " +
          model_with("[permanent]", "{method: bandpass, lines: [1001.02], lambda: .inf}") +
          " --out " + out,
      {"fit.lambda"});
  expect_refusal("calibrate --data " + files().flight + " --model " +
                     model_with("[permanent]",
                                "{method: bandpass, lines: [1001.02], band_hz: [1e-300, 0.9]}") +
                     " --out " + out,
                 {"fit.band_hz", "low cut-off"});
  // A flight whose tt steps by 1e-12 s.
  const FlightData& f = read_flight_h5(files().flight);
  Eigen::VectorXd tt = f.tt();
  for (Eigen::Index i = 0; i < tt.size(); ++i) tt[i] = 36000.0 + 1e-12 * static_cast<double>(i);
  const std::string tiny = flight_with("tiny_dt.h5", "tt", tt);
  expect_refusal("calibrate --data " + tiny + " --model " + files().model + " --out " + out,
                 {"tiny_dt.h5", "'tt'", "below 1 microsecond"});
  EXPECT_FALSE(exists(out));
  // A model file with a NaN coefficient is refused where it is loaded (node and CLI alike).
  std::string text = slurp(files().fitted);
  const auto at = text.find("permanent.x: ");
  ASSERT_NE(at, std::string::npos);
  text.replace(at, text.find('\n', at) - at, "permanent.x: .nan");
  expect_refusal("evaluate --data " + files().flight + " --model " + write("nan_coef.yaml", text),
                 {"nan_coef.yaml", "coefficients.permanent.x", "not finite"});
}

TEST(HostileInput, NothingToScoreIsAnErrorNotAScoreOfZero) {
  const Eigen::Index n = read_flight_h5(files().flight).size();
  const double nan = std::numeric_limits<double>::quiet_NaN();
  const std::string all_nan =
      flight_with("all_nan.h5", "mag_5_uc", Eigen::VectorXd::Constant(n, nan));
  expect_refusal("evaluate --data " + all_nan + " --model " + files().fitted,
                 {"all_nan.h5", "nothing to score"});
  const std::string all_inf =
      flight_with("all_inf.h5", "mag_5_uc",
                  Eigen::VectorXd::Constant(n, std::numeric_limits<double>::infinity()));
  // Infinity is no magnetometer's reading: refused by field and sample before any figure.
  expect_refusal("evaluate --data " + all_inf + " --model " + files().fitted,
                 {"all_inf.h5", "field 'mag_5_uc' holds inf nT at sample 0"});
  FlightData zero = read_flight_h5(files().flight);
  for (const char* c : {"flux_c_x", "flux_c_y", "flux_c_z"}) zero.set(c, Eigen::VectorXd::Zero(n));
  write_flight_h5(zero, files().dir + "/zero_flux.h5");
  expect_refusal("evaluate --data " + files().dir + "/zero_flux.h5 --model " + files().fitted,
                 {"zero_flux.h5", "nothing to score"});
  // Readings within any field and a model whose correction is not: the model is named, not the
  // data (a term sized where its channel barely moved reads it far beyond that elsewhere).
  std::string text = slurp(files().fitted);
  const auto at = text.find("permanent.x: ");
  ASSERT_NE(at, std::string::npos);
  text.replace(at, text.find('\n', at) - at, "permanent.x: 1e12");
  expect_refusal("evaluate --data " + files().flight + " --model " + write("huge_coef.yaml", text),
                 {"after the model has an rms of", "before the model's correction",
                  "the model's correction leaves the range of any field", "nothing to score"});
}

TEST(HostileInput, DeclaredSizesAreCheckedBeforeAnyAllocation) {
  // A dataset declared 2^40 values long that was never written, beside a valid flight.
  const std::string p = files().dir + "/huge.h5";
  write_flight_h5(read_flight_h5(files().flight), p);
  {
    const hid_t file = H5Fopen(p.c_str(), H5F_ACC_RDWR, H5P_DEFAULT);
    ASSERT_GE(file, 0);
    hsize_t dims = 1ull << 40, maxdims = H5S_UNLIMITED, chunk = 1024;
    const hid_t space = H5Screate_simple(1, &dims, &maxdims);
    const hid_t plist = H5Pcreate(H5P_DATASET_CREATE);
    H5Pset_chunk(plist, 1, &chunk);
    const hid_t ds =
        H5Dcreate2(file, "mag_9_uc", H5T_IEEE_F64LE, space, H5P_DEFAULT, plist, H5P_DEFAULT);
    ASSERT_GE(ds, 0);
    H5Dclose(ds);
    H5Pclose(plist);
    H5Sclose(space);
    H5Fclose(file);
  }
  expect_refusal("evaluate --data " + p + " --model " + files().fitted, {"huge.h5", "'mag_9_uc'"});
  // tt itself declared 1e8 long and never written, in a file of a few kB.
  const std::string q = files().dir + "/huge_tt.h5";
  {
    const hid_t file = H5Fcreate(q.c_str(), H5F_ACC_TRUNC, H5P_DEFAULT, H5P_DEFAULT);
    hsize_t dims = 100000000, chunk = 4096;
    const hid_t space = H5Screate_simple(1, &dims, nullptr);
    const hid_t plist = H5Pcreate(H5P_DATASET_CREATE);
    H5Pset_chunk(plist, 1, &chunk);
    const hid_t ds = H5Dcreate2(file, "tt", H5T_IEEE_F64LE, space, H5P_DEFAULT, plist, H5P_DEFAULT);
    H5Dclose(ds);
    H5Pclose(plist);
    H5Sclose(space);
    H5Fclose(file);
  }
  expect_refusal("evaluate --data " + q + " --model " + files().fitted,
                 {"huge_tt.h5", "'tt'", "declares 100000000 values"});
}

TEST(HostileInput, NothingIsLeftOutWithoutAWord) {
  // A string dataset, a boolean one and a group beside the flight.
  const std::string p = files().dir + "/extras.h5";
  write_flight_h5(read_flight_h5(files().flight), p);
  {
    const hid_t file = H5Fopen(p.c_str(), H5F_ACC_RDWR, H5P_DEFAULT);
    const hid_t str = H5Tcopy(H5T_C_S1);
    H5Tset_size(str, 8);
    hsize_t one = 1;
    const hid_t space = H5Screate_simple(1, &one, nullptr);
    const hid_t ds = H5Dcreate2(file, "pilot", str, space, H5P_DEFAULT, H5P_DEFAULT, H5P_DEFAULT);
    H5Dwrite(ds, str, H5S_ALL, H5S_ALL, H5P_DEFAULT, "ACE     ");
    H5Dclose(ds);
    const hid_t g = H5Gcreate2(file, "extra_group", H5P_DEFAULT, H5P_DEFAULT, H5P_DEFAULT);
    H5Gclose(g);
    H5Sclose(space);
    H5Tclose(str);
    H5Fclose(file);
  }
  // convert is lossless: it refuses, naming each object, unless told to leave them out.
  std::string out;
  EXPECT_EQ(test::run(test::cli() + " convert " + p + " " + files().dir + "/extras.bag", &out), 2);
  EXPECT_NE(out.find("field 'pilot' is a string dataset"), std::string::npos) << out;
  EXPECT_NE(out.find("'extra_group' is a group"), std::string::npos) << out;
  EXPECT_NE(out.find("--allow-skip"), std::string::npos) << out;
  EXPECT_FALSE(exists(files().dir + "/extras.bag"));
  EXPECT_EQ(
      test::run(test::cli() + " convert --allow-skip " + p + " " + files().dir + "/extras.bag",
                &out),
      0)
      << out;
  EXPECT_NE(out.find("warning: "), std::string::npos);
  // Other commands read on and say what they left out.
  EXPECT_EQ(test::run(test::cli() + " evaluate --data " + p + " --model " + files().fitted, &out),
            0);
  EXPECT_NE(out.find("warning: " + p + ": field 'pilot' is a string dataset"), std::string::npos)
      << out;
}

TEST(HostileInput, InfoReadsEveryFieldAndACorruptOneIsOneLine) {
  Eigen::VectorXd with_nan = read_flight_h5(files().flight).column("cur_strb");
  with_nan[3] = with_nan[7] = with_nan[11] = std::numeric_limits<double>::quiet_NaN();
  const std::string p = flight_with("info_nan.h5", "cur_strb", with_nan);
  std::string out;
  ASSERT_EQ(test::run(test::cli() + " info --data " + p, &out), 0) << out;
  const FlightData f = read_flight_h5(p);
  EXPECT_NE(out.find(std::to_string(f.size()) + " samples"), std::string::npos) << out;
  EXPECT_NE(out.find(std::to_string(f.names().size()) + " fields"), std::string::npos) << out;
  std::istringstream lines(out);
  int rows = 0;
  for (std::string line; std::getline(lines, line);) {
    std::istringstream words(line);
    std::string name;
    long nan = -1;
    words >> name >> nan;
    if (!f.has(name) || !words) continue;
    ++rows;
    if (name == "cur_strb") {
      EXPECT_EQ(nan, 3) << line;
    }
    if (name == "tt") {
      EXPECT_EQ(nan, 0) << line;
    }
  }
  EXPECT_EQ(rows, static_cast<int>(f.names().size())) << out;
  // A file (found by fuzzing) whose flux_c_z data cannot be read (its number type, corrupt, is
  // 4 GB wide): its structure is sound, so the other commands would meet it only when they need
  // that field; info reads every one.
  expect_refusal("info --data " + test::source_dir() + "/test/cli/data/corrupt_flux_c_z_data.h5",
                 {"corrupt_flux_c_z_data.h5", "field 'flux_c_z'", "(corrupt type)"});
}

TEST(HostileInput, AScenarioWithNonFiniteOrHugeNumbersIsRefused) {
  const std::string base = slurp(test::source_dir() + "/config/scenarios/rostest_short.yaml");
  auto with = [&](const std::string& from, const std::string& to) {
    std::string s = base;
    const auto at = s.find(from);
    EXPECT_NE(at, std::string::npos) << from;
    s.replace(at, from.size(), to);
    return write("scenario_" + std::to_string(std::hash<std::string>()(to)) + ".yaml", s);
  };
  const std::string out = files().dir + "/never.h5";
  expect_refusal("simulate --scenario " + with("lat_deg: 45.3", "lat_deg: .nan") + " --out " + out,
                 {"origin.lat_deg", "finite"});
  expect_refusal(
      "simulate --scenario " + with("speed_mps: 60", "speed_mps: .inf") + " --out " + out,
      {"aircraft.speed_mps", "finite"});
  expect_refusal(
      "simulate --scenario " + with("duration_s: 60", "duration_s: 1e12") + " --out " + out,
      {"duration_s"});
  EXPECT_FALSE(exists(out));
}

TEST(HostileInput, ATimeBaseWithNanOrInfIsRefusedByName) {
  Eigen::VectorXd tt = read_flight_h5(files().flight).tt();
  tt[17] = std::numeric_limits<double>::quiet_NaN();
  tt[40] = std::numeric_limits<double>::quiet_NaN();
  expect_refusal(
      "evaluate --data " + flight_with("tt_nan.h5", "tt", tt) + " --model " + files().fitted,
      {"tt_nan.h5", "'tt' has 2 non-finite value(s) (NaN at sample 17)"});
  tt = read_flight_h5(files().flight).tt();
  tt[4366 % tt.size()] = std::numeric_limits<double>::infinity();
  expect_refusal(
      "evaluate --data " + flight_with("tt_inf.h5", "tt", tt) + " --model " + files().fitted,
      {"'tt' has 1 non-finite value(s) (Inf at sample"});
}

TEST(HostileInput, OutputsNeverReplaceAnInputOrADevice) {
  const std::string before = slurp(files().flight);
  expect_refusal("calibrate --data " + files().flight + " --model " + files().model + " --out " +
                     files().flight,
                 {"f.h5", "is an input of this command"});
  expect_refusal("evaluate --data " + files().flight + " --model " + files().fitted + " --json " +
                     files().flight,
                 {"is an input of this command"});
  expect_refusal("evaluate --data " + files().flight + " --model " + files().fitted + " --json " +
                     files().fitted,
                 {"is an input of this command"});
  expect_refusal("simulate --scenario " + test::source_dir() +
                     "/config/scenarios/rostest_short.yaml --out /dev/full",
                 {"/dev/full", "not a regular file"});
  expect_refusal(
      "evaluate --data " + files().flight + " --model " + files().fitted + " --json /dev/full",
      {"/dev/full", "not a regular file"});
  expect_refusal("diagnose --data " + files().flight + " --model " + files().fitted +
                     " --json /dev/full --channels-only",
                 {"/dev/full"});
  // The same file under another name (a hard link) is still the input.
  const std::string link = files().dir + "/link.h5";
  ASSERT_EQ(::link(files().flight.c_str(), link.c_str()), 0);
  expect_refusal(
      "calibrate --data " + files().flight + " --model " + files().model + " --out " + link,
      {"link.h5", "is an input of this command"});
  EXPECT_EQ(slurp(files().flight), before);
}

TEST(HostileInput, ANetworksAttributionIsCheckedFieldByField) {
  const std::string dx = "diagnose --data " + files().flight + " --model " + files().fitted +
                         " --channels-only --attribution ";
  const std::vector<std::pair<std::string, std::vector<std::string>>> cases = {
      {"no json", {"att_0.json", "not JSON"}},
      {"{\"rmse_nT\": 1.0}", {"att_1.json", "no attribution"}},
      {"{\"attribution\": {\"channels\": 3}}",
       {"att_2.json", "attribution.channels", "not an array"}},
      {"{\"attribution\": {\"channels\": [{\"channel\": \"cur_strb\", \"share\": 1.5}]}}",
       {"att_3.json", "attribution.channels[0].share", "not in [0, 1]"}},
      {"{\"channels\": [{\"channel\": \"cur_strb\", \"share\": 0.5}, {\"channel\": "
       "\"cur_heat\", \"share\": null}]}",
       {"att_4.json", "attribution.channels[1].share", "not a number"}},
      {"{\"flights\": [{\"attribution\": {\"channels\": []}}, {\"attribution\": "
       "{\"channels\": [{\"share\": 0.3}]}}]}",
       {"att_5.json", "flights[1].attribution.channels[0].channel"}},
      {"{\"attribution\": {\"channels\": [{\"channel\": \"\", \"share\": 0.3}]}}",
       {"att_6.json", "attribution.channels[0].channel", "not a channel name"}}};
  for (size_t k = 0; k < cases.size(); ++k) {
    const std::string path = write("att_" + std::to_string(k) + ".json", cases[k].first);
    expect_refusal(dx + path, cases[k].second);
  }
  expect_refusal(dx + files().dir + "/absent.json", {"absent.json", "cannot be read"});
  // The diagnosis's JSON never replaces the attribution it reads.
  const std::string att = write("att_ok.json",
                                "{\"channels\": [{\"channel\": \"cur_strb\", "
                                "\"share\": 0.6}]}");
  const std::string before = slurp(att);
  expect_refusal(dx + att + " --json " + att, {"att_ok.json", "is an input of this command"});
  EXPECT_EQ(slurp(att), before);
}

TEST(HostileInput, ACorruptBagIsOneLineNotAnAbort) {
  const std::string bag = files().dir + "/good.bag";
  std::string out;
  ASSERT_EQ(test::run(test::cli() + " convert " + files().flight + " " + bag, &out), 0) << out;
  const std::string good = slurp(bag);
  // A valid header followed by random bytes.
  std::string bad = good.substr(0, 4200);
  unsigned state = 1;
  for (int i = 0; i < 300000; ++i) {
    state = state * 1103515245u + 12345u;
    bad.push_back(static_cast<char>(state >> 16));
  }
  std::ofstream(files().dir + "/random_tail.bag", std::ios::binary) << bad;
  expect_refusal("convert " + files().dir + "/random_tail.bag " + files().dir + "/o1.h5",
                 {"random_tail.bag", "not a readable rosbag"});
  // Truncated in the middle, and a connection header whose field length runs past its end.
  std::ofstream(files().dir + "/truncated.bag", std::ios::binary)
      << good.substr(0, good.size() / 2);
  expect_refusal("convert " + files().dir + "/truncated.bag " + files().dir + "/o2.h5",
                 {"truncated.bag", "not a readable rosbag"});
  std::ofstream(files().dir + "/empty.bag", std::ios::binary) << "";
  expect_refusal("convert " + files().dir + "/empty.bag " + files().dir + "/o3.h5", {"empty.bag"});
  for (const char* o : {"/o1.h5", "/o2.h5", "/o3.h5"}) EXPECT_FALSE(exists(files().dir + o));
}

}  // namespace
}  // namespace magcomp
