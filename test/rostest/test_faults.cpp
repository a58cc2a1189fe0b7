// rostest: NaN, duplicate, out-of-order, gap and time-jump inputs leave the compensator alive and
// counted in its diagnostics.
#include <diagnostic_msgs/DiagnosticArray.h>
#include <gtest/gtest.h>
#include <magcomp/AuxChannels.h>
#include <magcomp/CompensatedField.h>
#include <magcomp/ScalarMagnetometer.h>
#include <ros/ros.h>
#include <sensor_msgs/MagneticField.h>

#include <atomic>
#include <map>
#include <mutex>

#include "magcomp/core/io/flight_data.h"
#include "rostest_util.h"

namespace {

std::mutex g_mutex;
std::map<std::string, std::string> g_diag;
std::atomic<long> g_outputs{0};
std::atomic<double> g_last_output_t{0};

void on_diag(const diagnostic_msgs::DiagnosticArray::ConstPtr& a) {
  std::lock_guard<std::mutex> lock(g_mutex);
  for (const auto& s : a->status) {
    if (s.name.find("compensator") == std::string::npos) continue;
    for (const auto& kv : s.values) g_diag[kv.key] = kv.value;
    g_diag["level"] = std::to_string(static_cast<int>(s.level));
  }
}

void on_output(const magcomp::CompensatedField::ConstPtr& m) {
  ++g_outputs;
  g_last_output_t = m->header.stamp.toSec();
}

TEST(Faults, NodeSurvivesAndReportsEveryFault) {
  ros::NodeHandle nh, pnh("~");
  std::string h5;
  ASSERT_TRUE(pnh.getParam("h5", h5));
  const magcomp::FlightData f = magcomp::read_flight_h5(h5);
  auto scalar = nh.advertise<magcomp::ScalarMagnetometer>("/magcomp/scalar/mag_5_uc", 1000);
  auto vec = nh.advertise<sensor_msgs::MagneticField>("/magcomp/fluxgate/flux_c", 1000);
  auto aux = nh.advertise<magcomp::AuxChannels>("/magcomp/aux", 1000);
  ros::Subscriber sd = nh.subscribe("/diagnostics", 100, on_diag);
  ros::Subscriber so = nh.subscribe("/magcomp/compensated", 10000, on_output);
  const ros::WallTime t0 = ros::WallTime::now();
  while ((scalar.getNumSubscribers() == 0 || vec.getNumSubscribers() == 0 ||
          aux.getNumSubscribers() == 0) &&
         (ros::WallTime::now() - t0).toSec() < 20.0) {
    ros::WallDuration(0.1).sleep();
  }
  ASSERT_GT(scalar.getNumSubscribers(), 0u);
  const double base = 1.6e9;  // stamps: a fixed epoch + tt
  auto send = [&](Eigen::Index i, double t_override, bool nan_scalar) {
    const double t = t_override > 0 ? t_override : base + f.tt()[i] - f.tt()[0];
    sensor_msgs::MagneticField v;
    v.header.stamp = ros::Time(t);
    v.magnetic_field.x = f.column("flux_c_x")[i] * 1e-9;
    v.magnetic_field.y = f.column("flux_c_y")[i] * 1e-9;
    v.magnetic_field.z = f.column("flux_c_z")[i] * 1e-9;
    vec.publish(v);
    magcomp::AuxChannels a;
    a.header.stamp = v.header.stamp;
    a.names = {"cur_strb"};
    a.values = {f.column("cur_strb")[i]};
    aux.publish(a);
    magcomp::ScalarMagnetometer s;
    s.header.stamp = v.header.stamp;
    s.field_nT = nan_scalar ? std::numeric_limits<double>::quiet_NaN() : f.column("mag_5_uc")[i];
    scalar.publish(s);
    ros::WallDuration(0.002).sleep();
  };
  {  // an aux message whose names and values disagree: dropped and counted
    magcomp::AuxChannels bad;
    bad.header.stamp = ros::Time(base + 0.05);
    bad.names = {"cur_strb", "cur_heat"};
    bad.values = {1.0};
    aux.publish(bad);
  }
  for (Eigen::Index i = 0; i < 300; ++i) {
    if (i >= 250 && i < 280) continue;   // a 3 s gap
    send(i, -1, i == 100);               // NaN at 100
    if (i == 150) send(i, -1, false);    // duplicate stamp
    if (i == 200) send(195, -1, false);  // out of order (0.5 s back)
  }
  ros::WallDuration(1.5).sleep();
  const long before_jump = g_outputs;
  for (Eigen::Index i = 0; i < 60; ++i) send(i, -1, false);  // back to the start: a 30 s jump
  ros::WallDuration(3.0).sleep();                            // flush + two diagnostics periods
  EXPECT_GT(before_jump, 200);
  EXPECT_GT(g_outputs - before_jump, 40) << "no output after the jump back: the node did not reset";
  EXPECT_LT(g_last_output_t, base + 10.0);
  std::lock_guard<std::mutex> lock(g_mutex);
  auto count = [&](const char* k) { return g_diag.count(k) ? std::stol(g_diag[k]) : -1; };
  EXPECT_GE(count("nan_scalar"), 1);
  EXPECT_GE(count("duplicate_stamps"), 1);
  EXPECT_GE(count("out_of_order_dropped"), 1);
  EXPECT_GE(count("gaps"), 1);
  EXPECT_GE(count("time_jumps_back"), 1);
  EXPECT_EQ(count("aux_length_mismatch_dropped"), 1);
  EXPECT_EQ(g_diag["level"], "1");  // WARN: running, with input faults seen
  for (const auto& [k, v] : g_diag) std::printf("  %s = %s\n", k.c_str(), v.c_str());
}

}  // namespace

int main(int argc, char** argv) {
  return magcomp::rostest_util::run_tests(argc, argv, "test_faults", 2);
}
