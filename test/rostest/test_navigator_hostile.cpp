// rostest: the navigator (node and nodelet) fed valid INS samples and anomalies on MagNav.jl's
// simple map, with hostile messages between them. Every published fix, pose and odometry is
// finite; each fault is counted in the diagnostics; both are alive at the end.
#include <gtest/gtest.h>
#include <magcomp/CompensatedField.h>
#include <nav_msgs/Odometry.h>
#include <ros/ros.h>
#include <sensor_msgs/Imu.h>
#include <sensor_msgs/NavSatFix.h>
#include <std_msgs/Time.h>

#include <cmath>
#include <limits>
#include <mutex>

#include "magcomp/core/math/constants.h"
#include "magcomp/core/nav/anomaly_map.h"
#include "rostest_util.h"

namespace {

using namespace magcomp;

// One navigator's inputs and what it publishes.
struct Target {
  Target(ros::NodeHandle& nh, const std::string& ns, const std::string& status_name)
      : diagnostics(nh, status_name) {
    fix = nh.advertise<sensor_msgs::NavSatFix>(ns + "/magcomp/ins/solution", 1000);
    imu = nh.advertise<sensor_msgs::Imu>(ns + "/magcomp/ins/imu", 1000);
    anomaly = nh.advertise<magcomp::CompensatedField>(ns + "/magcomp/compensated", 1000);
    end = nh.advertise<std_msgs::Time>(ns + "/magcomp/end_of_stream", 10);
    sub_fix = nh.subscribe(ns + "/magcomp/nav/fix", 10000, &Target::on_fix, this);
    sub_odom = nh.subscribe(ns + "/magcomp/nav/odometry", 10000, &Target::on_odom, this);
  }
  void on_fix(const sensor_msgs::NavSatFix::ConstPtr& m) {
    std::lock_guard<std::mutex> lock(mutex);
    ++fixes;
    const bool ok =
        std::isfinite(m->latitude) && std::isfinite(m->longitude) && std::isfinite(m->altitude);
    bool cov = true;
    for (double c : m->position_covariance) cov &= std::isfinite(c);
    non_finite += !(ok && cov);
  }
  void on_odom(const nav_msgs::Odometry::ConstPtr& m) {
    std::lock_guard<std::mutex> lock(mutex);
    ++odometry;
    bool ok = std::isfinite(m->pose.pose.position.x) && std::isfinite(m->pose.pose.position.y) &&
              std::isfinite(m->pose.pose.position.z) && std::isfinite(m->twist.twist.linear.x);
    for (double c : m->pose.covariance) ok &= std::isfinite(c);
    non_finite += !ok;
  }
  // An INS sample (fix and attitude at one stamp) and its anomaly.
  void sample(const ros::Time& stamp, double lat, double lon, double alt, double anomaly_nT,
              int8_t status = sensor_msgs::NavSatStatus::STATUS_FIX) {
    sensor_msgs::NavSatFix f;
    f.header.stamp = stamp;
    f.status.status = status;
    f.latitude = lat;
    f.longitude = lon;
    f.altitude = alt;
    fix.publish(f);
    sensor_msgs::Imu i;
    i.header.stamp = stamp;
    i.orientation.w = 1.0;
    imu.publish(i);
    magcomp::CompensatedField a;
    a.header.stamp = stamp;
    a.anomaly_nT = anomaly_nT;
    a.variance_nT2 = NAN;
    anomaly.publish(a);
  }
  ros::Publisher fix, imu, anomaly, end;
  ros::Subscriber sub_fix, sub_odom;
  rostest_util::DiagnosticsCollector diagnostics;
  std::mutex mutex;
  long fixes = 0, odometry = 0, non_finite = 0;
};

TEST(NavigatorHostile, EveryOutputFiniteEveryFaultCountedNothingDies) {
  ros::NodeHandle nh, pnh("~");
  std::string map_path;
  ASSERT_TRUE(pnh.getParam("map", map_path));
  const nav::AnomalyMap map = nav::read_anomaly_map(map_path);
  Target node(nh, "/as_node", "hostile_node: navigator");
  Target nodelet(nh, "/as_nodelet", "hostile_manager: navigator");
  for (Target* t : {&node, &nodelet}) {
    // Both ways connected first: the navigator's inputs, and its outputs to this test.
    const auto connected = [t] {
      return t->fix.getNumSubscribers() > 0 && t->imu.getNumSubscribers() > 0 &&
             t->anomaly.getNumSubscribers() > 0 && t->end.getNumSubscribers() > 0 &&
             t->sub_fix.getNumPublishers() > 0 && t->sub_odom.getNumPublishers() > 0;
    };
    for (int k = 0; k < 400 && !connected(); ++k) ros::WallDuration(0.05).sleep();
    ASSERT_TRUE(connected());
  }
  // A straight line across the map's middle at 10 Hz, the anomaly the map's own value.
  const double lat0 = 0.5 * (map.lat_rad[0] + map.lat_rad[map.lat_rad.size() - 1]) * kRadToDeg;
  const double lon0 = 0.5 * (map.lon_rad[0] + map.lon_rad[map.lon_rad.size() - 1]) * kRadToDeg;
  const int n = 300;
  const double nan = std::numeric_limits<double>::quiet_NaN();
  long valid = 0;
  for (int k = 0; k < n; ++k) {
    const ros::Time stamp(1000.0 + 0.1 * k);
    const double lat = lat0 + 2e-5 * k, lon = lon0 + 1e-5 * k;
    const double z = map.value(lat * kDegToRad, lon * kDegToRad);
    for (Target* t : {&node, &nodelet}) {
      if (k == 50) {
        t->sample(stamp, 90.0, lon, 300, z);  // the pole
      } else if (k == 60) {
        t->sample(stamp, lat, lon, 1e300, z);  // off the Earth
      } else if (k == 70) {
        t->sample(stamp, lat, lon, 300, z, sensor_msgs::NavSatStatus::STATUS_NO_FIX);
      } else if (k == 80) {
        t->sample(stamp, nan, lon, 300, z);
      } else if (k == 90) {
        t->sample(stamp, lat, lon, 300, 1e300);  // an anomaly no magnetometer gives
      } else {
        t->sample(stamp, lat, lon, 300, z);
      }
    }
    valid += k != 50 && k != 60 && k != 70 && k != 80;
    ros::WallDuration(0.002).sleep();
  }
  // A stamp at the edge of ROS time, then the end of the stream: the navigator must live on.
  ros::Time edge;
  edge.sec = 4294967295u;
  edge.nsec = 999999999u;
  for (Target* t : {&node, &nodelet}) {
    t->sample(edge, lat0, lon0, 300, 0.0);
    std_msgs::Time e;
    e.data = ros::Time(1000.0 + 0.1 * n);
    t->end.publish(e);
  }
  // Outputs settle, and the diagnostics (1 Hz) come after the end: both are alive.
  ros::WallDuration(4.0).sleep();
  for (Target* t : {&node, &nodelet}) {
    std::lock_guard<std::mutex> lock(t->mutex);
    std::printf("  %ld fixes, %ld odometry, %ld non-finite; diagnostics:", t->fixes, t->odometry,
                t->non_finite);
    for (const char* k : {"steps", "ins_refused", "ins_no_fix_dropped", "nan_inputs",
                          "measurements_refused", "stamps_out_of_range", "callback_errors"})
      std::printf(" %s=%ld", k, t->diagnostics.count(k));
    std::printf("\n");
    EXPECT_EQ(t->non_finite, 0);
    EXPECT_GE(t->fixes, valid - 5);                     // the last samples wait for the flush only
    EXPECT_GE(t->diagnostics.count("ins_refused"), 2);  // the pole and 1e300 m
    EXPECT_EQ(t->diagnostics.count("ins_no_fix_dropped"), 1);
    EXPECT_GE(t->diagnostics.count("nan_inputs"), 1);
    EXPECT_EQ(t->diagnostics.count("measurements_refused"), 1);
    EXPECT_GE(t->diagnostics.count("stamps_out_of_range"), 1);
    EXPECT_EQ(t->diagnostics.count("callback_errors"), 0);
  }
  // Still running: a later valid sample is taken (its counters move).
  const long steps_before = node.diagnostics.count("steps") + nodelet.diagnostics.count("steps");
  for (int k = 0; k < 30; ++k)
    for (Target* t : {&node, &nodelet})
      t->sample(ros::Time(2000.0 + 0.1 * k), lat0, lon0 + 1e-5 * k, 300,
                map.value(lat0 * kDegToRad, (lon0 + 1e-5 * k) * kDegToRad));
  ros::WallDuration(3.0).sleep();
  EXPECT_GT(node.diagnostics.count("steps") + nodelet.diagnostics.count("steps"),
            steps_before + 20);
}

}  // namespace

int main(int argc, char** argv) {
  return magcomp::rostest_util::run_tests(argc, argv, "test_navigator_hostile", 2);
}
