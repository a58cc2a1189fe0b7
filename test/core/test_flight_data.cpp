// FlightData: HDF5 schema read/write, naming generations, sorting, selection, and bad input.
#include <gtest/gtest.h>
#include <hdf5.h>
#include <unistd.h>

#include <cmath>
#include <cstring>
#include <fstream>
#include <functional>
#include <iterator>
#include <limits>

#include "magcomp/core/error.h"
#include "magcomp/core/io/file_io.h"
#include "magcomp/core/io/flight_data.h"
#include "test_util.h"

namespace magcomp {
namespace {

// Writes raw datasets with the HDF5 C API, bypassing our writer (to make odd files).
void write_raw(const std::string& path,
               const std::vector<std::pair<std::string, std::vector<double>>>& series,
               bool add_scalars = false, bool add_2d = false) {
  hid_t f = H5Fcreate(path.c_str(), H5F_ACC_TRUNC, H5P_DEFAULT, H5P_DEFAULT);
  for (const auto& [name, v] : series) {
    hsize_t n = v.size();
    hid_t s = H5Screate_simple(1, &n, nullptr);
    hid_t d = H5Dcreate2(f, name.c_str(), H5T_IEEE_F64LE, s, H5P_DEFAULT, H5P_DEFAULT, H5P_DEFAULT);
    H5Dwrite(d, H5T_NATIVE_DOUBLE, H5S_ALL, H5S_ALL, H5P_DEFAULT, v.data());
    H5Dclose(d);
    H5Sclose(s);
  }
  if (add_scalars) {
    for (auto [name, value] : {std::pair<const char*, double>{"N", 4.0}, {"dt", 0.0961}}) {
      hid_t s = H5Screate(H5S_SCALAR);
      hid_t d = H5Dcreate2(f, name, H5T_IEEE_F64LE, s, H5P_DEFAULT, H5P_DEFAULT, H5P_DEFAULT);
      H5Dwrite(d, H5T_NATIVE_DOUBLE, H5S_ALL, H5S_ALL, H5P_DEFAULT, &value);
      H5Dclose(d);
      H5Sclose(s);
    }
  }
  if (add_2d) {
    hsize_t dims[2] = {2, 2};
    double v[4] = {1, 2, 3, 4};
    hid_t s = H5Screate_simple(2, dims, nullptr);
    hid_t d = H5Dcreate2(f, "matrix", H5T_IEEE_F64LE, s, H5P_DEFAULT, H5P_DEFAULT, H5P_DEFAULT);
    H5Dwrite(d, H5T_NATIVE_DOUBLE, H5S_ALL, H5S_ALL, H5P_DEFAULT, v);
    H5Dclose(d);
    H5Sclose(s);
  }
  H5Fclose(f);
}

std::string expect_error(const std::function<void()>& fn) {
  try {
    fn();
  } catch (const Error& e) {
    return e.what();
  }
  ADD_FAILURE() << "no magcomp::Error thrown";
  return "";
}

TEST(FlightData, OlderNamesScalarsAndUnsortedTimeAreHandled) {
  const std::string dir = test::temp_dir("fd");
  const std::string path = dir + "/old.h5";
  const double nan = std::numeric_limits<double>::quiet_NaN();
  write_raw(path,
            {{"tt", {10.3, 10.0, 10.1, 10.2}},
             {"tie_line", {1001.01, 1001.01, 1001.01, 1002.0}},
             {"ins_azim", {3, 0, 1, 2}},
             {"utmX", {30, 0, 10, 20}},
             {"mag_1_uc", {nan, 50000.0, 50001.0, 50002.0}}},
            true);
  const FlightData d = read_flight_h5(path);
  EXPECT_EQ(d.size(), 4);
  EXPECT_TRUE(d.has("line"));
  EXPECT_TRUE(d.has("ins_yaw"));
  EXPECT_TRUE(d.has("utm_x"));
  EXPECT_TRUE(d.has("ins_azim"));  // old names still resolve
  EXPECT_FALSE(d.has("N"));
  EXPECT_DOUBLE_EQ(d.tt()[0], 10.0);
  EXPECT_DOUBLE_EQ(d.tt()[3], 10.3);
  EXPECT_DOUBLE_EQ(d.column("ins_yaw")[3], 3.0);  // rows moved with tt
  EXPECT_TRUE(std::isnan(d.column("mag_1_uc")[3]));
  EXPECT_NEAR(d.dt_s(), 0.1, 1e-9);  // derived from tt, not the file's 0.0961
  const auto sel = d.select({1002.0}, {{10.05, 10.15}});
  ASSERT_EQ(sel.size(), 2u);
  EXPECT_EQ(sel[0], 1);  // tt 10.1 by window
  EXPECT_EQ(sel[1], 2);  // tt 10.2 by line 1002
}

TEST(FlightData, WriteReadRoundTripIsBitIdentical) {
  const std::string dir = test::temp_dir("fd");
  FlightData d;
  const int n = 1000;
  Eigen::VectorXd tt(n), x(n);
  for (int i = 0; i < n; ++i) {
    tt[i] = 46000.0 + 0.1 * i;
    x[i] = std::sin(i * 0.123456789) * 1e4 + 1.0 / 3.0;
  }
  x[17] = std::numeric_limits<double>::quiet_NaN();
  d.set("tt", tt);
  d.set("mag_5_uc", x);
  d.set("line", Eigen::VectorXd::Constant(n, 1002.02));
  write_flight_h5(d, dir + "/rt.h5");
  const FlightData r = read_flight_h5(dir + "/rt.h5");
  ASSERT_EQ(r.size(), n);
  ASSERT_EQ(r.names().size(), 3u);
  for (int i = 0; i < n; ++i) {
    if (i == 17) {
      EXPECT_TRUE(std::isnan(r.column("mag_5_uc")[i]));
      continue;
    }
    ASSERT_EQ(std::memcmp(&x[i], r.column("mag_5_uc").data() + i, sizeof(double)), 0) << i;
    ASSERT_EQ(tt[i], r.tt()[i]);
  }
}

TEST(FlightData, BadInputsNameFileAndField) {
  const std::string dir = test::temp_dir("fd");
  EXPECT_NE(expect_error([&] { read_flight_h5(dir + "/missing.h5"); }).find("missing.h5"),
            std::string::npos);
  {
    std::ofstream f(dir + "/text.h5");
    f << "not hdf5\n";
  }
  EXPECT_NE(expect_error([&] { read_flight_h5(dir + "/text.h5"); }).find("not an HDF5 file"),
            std::string::npos);
  write_raw(dir + "/nott.h5", {{"mag_1_uc", {1, 2}}});
  EXPECT_NE(expect_error([&] { read_flight_h5(dir + "/nott.h5"); }).find("'tt'"),
            std::string::npos);
  FlightData d;
  d.set("tt", Eigen::VectorXd::LinSpaced(3, 0, 0.2));
  EXPECT_NE(expect_error([&] { d.column("flux_c_x"); }).find("'flux_c_x'"), std::string::npos);
  write_raw(dir + "/len.h5", {{"tt", {1, 2, 3}}, {"mag_1_uc", {1, 2}}});
  const std::string e = expect_error([&] { read_flight_h5(dir + "/len.h5"); });
  EXPECT_NE(e.find("len.h5"), std::string::npos) << e;
  EXPECT_NE(e.find("'mag_1_uc'"), std::string::npos) << e;
  write_raw(dir + "/rank.h5", {{"tt", {1, 2}}}, false, true);
  EXPECT_NE(expect_error([&] { read_flight_h5(dir + "/rank.h5"); }).find("'matrix'"),
            std::string::npos);
}

// Replaces every occurrence of the bytes `from` in the file at `path` by `to` (same length);
// returns how many there were.
int patch_bytes(const std::string& path, const std::string& from, const std::string& to) {
  std::ifstream in(path, std::ios::binary);
  std::string bytes((std::istreambuf_iterator<char>(in)), std::istreambuf_iterator<char>());
  in.close();
  int hits = 0;
  for (size_t at = bytes.find(from); at != std::string::npos; at = bytes.find(from, at + 1)) {
    bytes.replace(at, to.size(), to);
    ++hits;
  }
  std::ofstream(path, std::ios::binary) << bytes;
  return hits;
}

std::string le64(unsigned long long v) { return std::string(reinterpret_cast<char*>(&v), 8); }

TEST(FlightData, AFieldDeclaringMoreThanTheFileHoldsIsRefusedBeforeAnyAllocation) {
  const std::string dir = test::temp_dir("fd");
  std::vector<double> tt(37), mag(37);
  for (int i = 0; i < 37; ++i) tt[i] = 0.1 * i, mag[i] = 50000.0 + i;
  // A plain (contiguous) field whose shape says 300 values where 37 are stored: the dims and
  // max dims of both datasets, the only 8-byte words equal to 37 in the file.
  write_raw(dir + "/dims.h5", {{"tt", tt}, {"mag_1_uc", mag}});
  ASSERT_EQ(patch_bytes(dir + "/dims.h5", le64(37), le64(300)), 4);
  std::string e = expect_error([&] { read_flight_h5(dir + "/dims.h5"); });
  EXPECT_NE(e.find("dims.h5: field 'tt' declares 300 values (2400 bytes) but the file stores 296"),
            std::string::npos)
      << e;
  EXPECT_EQ(e.find('\n'), std::string::npos) << e;
  // A float type 2 GiB wide (a file the fuzzer wrote: converting it allocated count × its size):
  // the type message of an IEEE little-endian float64 (class 1 version 1, bit field 20 3f 00,
  // size 8) with its size set to 2^31 + 8.
  write_raw(dir + "/type.h5", {{"tt", tt}, {"mag_1_uc", mag}});
  const std::string f64("\x11\x20\x3f\x00\x08\x00\x00\x00", 8);
  const std::string wide("\x11\x20\x3f\x00\x08\x00\x00\x80", 8);
  ASSERT_EQ(patch_bytes(dir + "/type.h5", f64, wide), 2);
  e = expect_error([&] {
    const FlightData d = read_flight_h5(dir + "/type.h5");
    (void)d.column("mag_1_uc");
  });
  EXPECT_NE(e.find("type.h5: field '"), std::string::npos) << e;
  EXPECT_NE(e.find("has a 2147483656-byte number type (corrupt type)"), std::string::npos) << e;
}

TEST(FlightDataDeathTest, AFileTruncatedWhileReadInPlaceEndsInOneLine) {
  // A column read in place from its file: another program truncates the file under it.
  const std::string path = test::temp_dir("truncated") + "/flight.h5";
  FlightData d;
  const Eigen::Index n = 200000;
  d.set("tt", Eigen::VectorXd::LinSpaced(n, 0.0, 0.1 * static_cast<double>(n - 1)));
  d.set("mag_5_uc", Eigen::VectorXd::Constant(n, 50000.0));
  write_flight_h5(d, path);
  const FlightData r = read_flight_h5(path);
  ASSERT_NE(r.values_in_place("mag_5_uc"), nullptr);  // mapped, not copied
  EXPECT_EXIT(
      {
        exit_cleanly_on_truncated_file();
        if (::truncate(path.c_str(), 4096) != 0) std::exit(9);
        double sum = 0;
        const auto x = r.column("mag_5_uc");
        for (Eigen::Index i = 0; i < x.size(); ++i) sum += x[i];
        std::printf("%g\n", sum);
        std::exit(0);
      },
      ::testing::ExitedWithCode(2), "changed or truncated while it was read");
}

}  // namespace
}  // namespace magcomp
