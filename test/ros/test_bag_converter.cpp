// HDF5 -> bag -> HDF5 is bit-identical (every field, every sample, NaN kept); bad input is named.
#include <gtest/gtest.h>

#include <rosbag/bag.h>
#include <rosbag/view.h>
#include <sensor_msgs/NavSatFix.h>

#include <cstring>
#include <fstream>
#include <map>

#include "magcomp/core/error.h"
#include "magcomp/ros/bag_converter.h"
#include "scenario_cache.h"

namespace magcomp {
namespace {

TEST(BagConverter, RoundTripIsBitIdenticalWithNan) {
  const std::string dir = test::temp_dir("bag");
  sim::Scenario s = sim::load_scenario(test::source_dir() + "/config/scenarios/wire_strobe.yaml");
  s.segments.resize(1);
  FlightData f = sim::simulate(s, Igrf::installed()).flight;
  Eigen::VectorXd radar = f.column("radar");
  radar.segment(100, 50).setConstant(std::numeric_limits<double>::quiet_NaN());  // a radar gap
  f.set("radar", radar);
  write_flight_h5(f, dir + "/in.h5");
  std::string out;
  ASSERT_EQ(test::run(test::cli() + " convert " + dir + "/in.h5 " + dir + "/f.bag", &out), 0)
      << out;
  ASSERT_EQ(test::run(test::cli() + " convert " + dir + "/f.bag " + dir + "/back.h5", &out), 0)
      << out;
  const FlightData a = read_flight_h5(dir + "/in.h5");
  const FlightData b = read_flight_h5(dir + "/back.h5");
  ASSERT_EQ(a.names(), b.names());
  ASSERT_EQ(a.size(), b.size());
  long nan_kept = 0;
  for (const auto& name : a.names()) {
    const auto& x = a.column(name);
    const auto& y = b.column(name);
    ASSERT_EQ(std::memcmp(x.data(), y.data(), sizeof(double) * static_cast<size_t>(x.size())), 0)
        << name;
    nan_kept += x.array().isNaN().count();
  }
  EXPECT_GE(nan_kept, 50);
  // The bag (written by magcomp's own format-2.0 writer) reads back with rosbag itself: every
  // typed topic holds one message per sample, in time order, and the typed values are the file's.
  rosbag::Bag bag(dir + "/f.bag", rosbag::bagmode::Read);
  rosbag::View view(bag);
  std::map<std::string, long> per_topic;
  ros::Time last;
  long in_order = 0, total = 0;
  for (const rosbag::MessageInstance& m : view) {
    ++per_topic[m.getTopic()];
    in_order += m.getTime() >= last;
    last = m.getTime();
    ++total;
  }
  EXPECT_EQ(in_order, total);
  for (const char* t :
       {"/magcomp/flight_record", "/magcomp/scalar/mag_5_uc", "/magcomp/reference",
        "/magcomp/fluxgate/flux_c", "/magcomp/ins/imu", "/magcomp/ins/fix", "/magcomp/aux"}) {
    EXPECT_EQ(per_topic[t], a.size()) << t;
  }
  EXPECT_EQ(per_topic["/magcomp/flight_schema"], 1);
  rosbag::View fix_view(bag, rosbag::TopicQuery("/magcomp/ins/fix"));
  long k = 0;
  for (const rosbag::MessageInstance& m : fix_view) {
    const auto fix = m.instantiate<sensor_msgs::NavSatFix>();
    ASSERT_TRUE(fix);
    ASSERT_EQ(fix->latitude, a.column("lat")[k]) << k;
    ASSERT_EQ(m.getTime(), rosio::stamp_of(2020, static_cast<int>(a.column("doy")[k]), a.tt()[k]));
    ++k;
  }
  EXPECT_EQ(k, a.size());
  // Never overwrite without --force.
  EXPECT_NE(test::run(test::cli() + " convert " + dir + "/in.h5 " + dir + "/f.bag", &out), 0);
  EXPECT_NE(out.find("--force"), std::string::npos) << out;
  EXPECT_EQ(test::run(test::cli() + " convert --force " + dir + "/in.h5 " + dir + "/f.bag", &out),
            0)
      << out;
}

TEST(BagConverter, StampsComeFromYearDoyAndTt) {
  // 2020 day 181 = 29 June 2020; 00:00 UTC = 1593388800 s.
  EXPECT_DOUBLE_EQ(rosio::stamp_of(2020, 181, 0.0).toSec(), 1593388800.0);
  EXPECT_NEAR(rosio::stamp_of(2020, 181, 49820.1).toSec(), 1593388800.0 + 49820.1, 1e-6);
}

// The columns of two flight files are the same bits.
void expect_same_flight(const std::string& a_path, const std::string& b_path) {
  const FlightData a = read_flight_h5(a_path), b = read_flight_h5(b_path);
  ASSERT_EQ(a.names(), b.names()) << b_path;
  ASSERT_EQ(a.size(), b.size()) << b_path;
  for (const auto& name : a.names()) {
    const auto x = a.column(name), y = b.column(name);
    ASSERT_EQ(std::memcmp(x.data(), y.data(), sizeof(double) * static_cast<size_t>(x.size())), 0)
        << b_path << ": " << name;
  }
}

TEST(BagConverter, BagsTheStreamingReaderCannotTakeAreReadThroughTheIndex) {
  // bag_to_h5 reads a bag in one pass in file order; a bag with compressed chunks, or with its
  // records out of order in the file (time order intact), goes through rosbag's index instead.
  // Every way gives the source file back.
  const std::string dir = test::temp_dir("bag_paths");
  sim::Scenario s = sim::load_scenario(test::source_dir() + "/config/scenarios/wire_strobe.yaml");
  s.segments.resize(1);
  write_flight_h5(sim::simulate(s, Igrf::installed()).flight, dir + "/in.h5");
  rosio::flight_to_bag(read_flight_h5(dir + "/in.h5"), dir + "/plain.bag", false);
  rosio::bag_to_h5(dir + "/plain.bag", dir + "/plain.h5");
  expect_same_flight(dir + "/in.h5", dir + "/plain.h5");

  rosbag::Bag plain(dir + "/plain.bag", rosbag::bagmode::Read);
  std::vector<rosbag::MessageInstance> records;
  {
    rosbag::Bag compressed(dir + "/lz4.bag", rosbag::bagmode::Write);
    compressed.setCompression(rosbag::compression::LZ4);
    rosbag::Bag reversed(dir + "/reversed.bag", rosbag::bagmode::Write);
    rosbag::View all(plain);
    for (const rosbag::MessageInstance& m : all) {
      compressed.write(m.getTopic(), m.getTime(), m, m.getConnectionHeader());
      if (m.getTopic() == rosio::BagTopics::kRecord) {
        records.push_back(m);
      } else if (m.getTopic() == rosio::BagTopics::kSchema) {
        reversed.write(m.getTopic(), m.getTime(), m, m.getConnectionHeader());
      }
    }
    for (auto it = records.rbegin(); it != records.rend(); ++it)
      reversed.write(it->getTopic(), it->getTime(), *it, it->getConnectionHeader());
  }
  ASSERT_GT(records.size(), 1000u);
  rosio::bag_to_h5(dir + "/lz4.bag", dir + "/lz4.h5");
  expect_same_flight(dir + "/in.h5", dir + "/lz4.h5");
  rosio::bag_to_h5(dir + "/reversed.bag", dir + "/reversed.h5");
  expect_same_flight(dir + "/in.h5", dir + "/reversed.h5");
}

TEST(BagConverter, BadInputIsNamed) {
  const std::string dir = test::temp_dir("bag");
  FlightData f;
  f.set("tt", Eigen::VectorXd::LinSpaced(10, 0, 0.9));
  f.set("year", Eigen::VectorXd::Constant(10, 2020));
  f.set("doy", Eigen::VectorXd::Constant(10, 181));
  Eigen::VectorXd tt = f.tt();
  tt[4] = std::numeric_limits<double>::quiet_NaN();
  f.set("tt", tt);
  try {
    rosio::flight_to_bag(f, dir + "/x.bag", false);
    FAIL();
  } catch (const Error& e) {
    EXPECT_NE(std::string(e.what()).find("'tt' is NaN at sample 4"), std::string::npos) << e.what();
  }
  EXPECT_FALSE(std::ifstream(dir + "/x.bag").good());  // nothing half-written left behind
  std::ofstream(dir + "/junk.bag") << "junk";
  EXPECT_THROW(rosio::bag_to_flight(dir + "/junk.bag"), Error);
  FlightData g;
  g.set("tt", Eigen::VectorXd::LinSpaced(10, 0, 0.9));
  EXPECT_THROW(rosio::flight_to_bag(g, dir + "/y.bag", false), Error);  // no year: no stamps
}

}  // namespace
}  // namespace magcomp
