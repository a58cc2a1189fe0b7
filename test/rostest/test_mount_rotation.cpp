// rostest: fluxgate readings in a rotated sensor frame are rotated into base_link with tf2.
#include <gtest/gtest.h>
#include <magcomp/AuxChannels.h>
#include <magcomp/CompensatedField.h>
#include <magcomp/ScalarMagnetometer.h>
#include <ros/ros.h>
#include <sensor_msgs/MagneticField.h>

#include <cmath>
#include <mutex>

#include "magcomp/core/apply/apply.h"
#include "magcomp/core/model/model.h"
#include "rostest_util.h"

namespace {

TEST(MountRotation, RotatedFluxgateGivesTheOfflineCompensation) {
  ros::NodeHandle nh, pnh("~");
  std::string h5, model_path;
  ASSERT_TRUE(pnh.getParam("h5", h5));
  ASSERT_TRUE(pnh.getParam("model", model_path));
  const magcomp::FlightData f = magcomp::read_flight_h5(h5);
  const Eigen::VectorXd offline = magcomp::compensate(magcomp::load_model_yaml(model_path), f);
  auto scalar = nh.advertise<magcomp::ScalarMagnetometer>("/magcomp/scalar/mag_5_uc", 1000);
  auto vec = nh.advertise<sensor_msgs::MagneticField>("/magcomp/fluxgate/flux_c", 1000);
  auto aux = nh.advertise<magcomp::AuxChannels>("/magcomp/aux", 1000);
  magcomp::rostest_util::OutputCollector collector(nh);
  const ros::WallTime t0 = ros::WallTime::now();
  while ((scalar.getNumSubscribers() == 0 || vec.getNumSubscribers() == 0 ||
          aux.getNumSubscribers() == 0 || collector.subscriber().getNumPublishers() == 0) &&
         (ros::WallTime::now() - t0).toSec() < 20.0) {
    ros::WallDuration(0.1).sleep();
  }
  ros::WallDuration(1.5).sleep();  // the static mount reaches the compensator's tf2 buffer
  const int n = 400;
  const double base = 1600000000.0;
  for (int i = 0; i < n; ++i) {
    // Stamps exact to the nanosecond (a double near 1.6e9 s resolves only 2.4e-7 s).
    const double dt = f.tt()[i] - f.tt()[0];
    ros::Time t;
    t.sec = static_cast<uint32_t>(base) + static_cast<uint32_t>(std::floor(dt));
    t.nsec = static_cast<uint32_t>(std::llround((dt - std::floor(dt)) * 1e9) % 1000000000LL);
    // The sensor is turned +90 deg about z: in its frame, x_s = y_b and y_s = -x_b.
    sensor_msgs::MagneticField v;
    v.header.stamp = t;
    v.header.frame_id = "flux_c_rotated";
    v.magnetic_field.x = f.column("flux_c_y")[i] * 1e-9;
    v.magnetic_field.y = -f.column("flux_c_x")[i] * 1e-9;
    v.magnetic_field.z = f.column("flux_c_z")[i] * 1e-9;
    vec.publish(v);
    magcomp::AuxChannels a;
    a.header.stamp = t;
    a.names = {"cur_strb"};
    a.values = {f.column("cur_strb")[i]};
    aux.publish(a);
    magcomp::ScalarMagnetometer s;
    s.header.stamp = t;
    s.field_nT = f.column("mag_5_uc")[i];
    scalar.publish(s);
    ros::WallDuration(0.002).sleep();
  }
  ros::WallDuration(2.0).sleep();  // the end-of-stream flush
  const std::vector<magcomp::CompensatedField> g_out = collector.outputs();
  ASSERT_EQ(g_out.size(), static_cast<size_t>(n));
  double worst = 0;
  for (int i = 2; i < n - 10; ++i) {  // away from the stream's ends (one-sided differences there)
    if (!std::isfinite(offline[i])) continue;
    worst = std::max(worst, std::abs(g_out[static_cast<size_t>(i)].compensated_nT - offline[i]));
  }
  std::printf("  rotated fluxgate: worst |online - offline| = %.2e nT over %d samples\n", worst, n);
  EXPECT_LT(worst, 1e-6);
}

}  // namespace

int main(int argc, char** argv) {
  return magcomp::rostest_util::run_tests(argc, argv, "test_mount_rotation", 1);
}
