// rostest: the compensator node fed by `rosbag play` reproduces the offline compensation.
#include <gtest/gtest.h>
#include <magcomp/CompensatedField.h>
#include <ros/ros.h>

#include <cmath>
#include <mutex>

#include "magcomp/core/model.h"
#include "magcomp/ros/bag_converter.h"

namespace {

std::mutex g_mutex;
std::vector<magcomp::CompensatedField> g_out;

void on_output(const magcomp::CompensatedField::ConstPtr& m) {
  std::lock_guard<std::mutex> lock(g_mutex);
  g_out.push_back(*m);
}

TEST(OnlineOffline, WholeReplayedFlightEqualsOfflineWithNoSampleLost) {
  ros::NodeHandle nh, pnh("~");
  std::string h5, model_path;
  double tol = 1e-6;
  ASSERT_TRUE(pnh.getParam("h5", h5));
  ASSERT_TRUE(pnh.getParam("model", model_path));
  pnh.param("tolerance_rms_nT", tol, 1e-6);
  const magcomp::FlightData f = magcomp::read_flight_h5(h5);
  const magcomp::Model m = magcomp::load_model_yaml(model_path);
  const Eigen::VectorXd offline = magcomp::compensate(m, f);
  const Eigen::VectorXd& ref = f.column("mag_1_c");
  ros::Subscriber sub = nh.subscribe("/magcomp/compensated", 100000, on_output);
  // Wait for the whole flight (the node flushes its last samples when the bag ends).
  const ros::WallTime start = ros::WallTime::now();
  size_t last_count = 0;
  ros::WallTime last_change = start;
  while ((ros::WallTime::now() - start).toSec() < 200.0) {
    ros::WallDuration(0.2).sleep();
    std::lock_guard<std::mutex> lock(g_mutex);
    if (g_out.size() != last_count) {
      last_count = g_out.size();
      last_change = ros::WallTime::now();
    }
    if (last_count >= static_cast<size_t>(f.size())) break;
    if (last_count > 0 && (ros::WallTime::now() - last_change).toSec() > 8.0) break;
  }
  std::lock_guard<std::mutex> lock(g_mutex);
  ASSERT_EQ(g_out.size(), static_cast<size_t>(f.size())) << "samples lost or duplicated";
  const int year = static_cast<int>(f.column("year")[0]),
            doy = static_cast<int>(f.column("doy")[0]);
  double ss = 0, ss_err = 0;
  long finite = 0;
  for (Eigen::Index i = 0; i < f.size(); ++i) {
    const auto& o = g_out[static_cast<size_t>(i)];
    ASSERT_NEAR(o.header.stamp.toSec(), magcomp::rosio::stamp_of(year, doy, f.tt()[i]).toSec(),
                1e-6)
        << i;
    if (!std::isfinite(offline[i])) {
      EXPECT_FALSE(std::isfinite(o.compensated_nT)) << i;
      continue;
    }
    if (!std::isfinite(o.compensated_nT)) {
      ADD_FAILURE() << "online NaN at sample " << i << " of " << f.size() << " (offline "
                    << offline[i] << ")";
      continue;
    }
    ss += std::pow(o.compensated_nT - offline[i], 2);
    ss_err += std::pow(o.error_nT - (offline[i] - ref[i]), 2);
    ++finite;
  }
  const double rms = std::sqrt(ss / finite), rms_err = std::sqrt(ss_err / finite);
  std::printf("  %ld samples; online vs offline: rms %.3e nT (live error rms diff %.3e nT)\n",
              finite, rms, rms_err);
  EXPECT_LT(rms, tol);
  EXPECT_LT(rms_err, tol);
  EXPECT_GT(finite, f.size() - 10);
}

}  // namespace

int main(int argc, char** argv) {
  testing::InitGoogleTest(&argc, argv);
  ros::init(argc, argv, "test_online_offline");
  ros::AsyncSpinner spinner(1);
  spinner.start();
  return RUN_ALL_TESTS();
}
