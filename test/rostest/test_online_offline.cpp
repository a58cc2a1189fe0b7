// rostest: the compensator node fed by `rosbag play` reproduces the offline compensation.
#include <gtest/gtest.h>
#include <magcomp/CompensatedField.h>
#include <ros/ros.h>
#include <sensor_msgs/MagneticField.h>

#include <cmath>
#include <mutex>

#include "magcomp/core/apply/apply.h"
#include "magcomp/core/model/model.h"
#include "magcomp/core/neural/network.h"
#include "magcomp/ros/bag_converter.h"
#include "rostest_util.h"

namespace {

TEST(OnlineOffline, WholeReplayedFlightEqualsOfflineWithNoSampleLost) {
  ros::NodeHandle nh, pnh("~");
  std::string h5, model_path;
  double tol = 1e-6;
  ASSERT_TRUE(pnh.getParam("h5", h5));
  ASSERT_TRUE(pnh.getParam("model", model_path));
  pnh.param("tolerance_rms_nT", tol, 1e-6);
  const magcomp::FlightData f = magcomp::read_flight_h5(h5);
  const magcomp::Model m = magcomp::load_model_yaml(model_path);
  // A model with a neural stage: the offline path is the batch inference (windows padded at
  // the flight's start, as the node's ring buffer is).
  const Eigen::VectorXd offline = magcomp::compensate(m, f);  // the neural stage included
  if (m.neural)
    std::printf("  neural stage: %s, %s mode, window %d\n",
                magcomp::architecture_name(m.neural->architecture),
                magcomp::mode_name(m.neural->mode), m.neural->window);
  const auto ref = f.column("mag_1_c");
  magcomp::rostest_util::OutputCollector collector(nh);
  magcomp::rostest_util::DiagnosticsCollector diagnostics(nh);
  // Fault injection: one input relayed with random wall delays (its order kept).
  const auto relay =
      magcomp::rostest_util::relay_from_params<sensor_msgs::MagneticField>(nh, pnh, 7u);
  // A `rosbag play --pause` player (param player_paused): the replay begins once the node's
  // output reaches this test. (The Player nodelet waits for the compensator by itself.)
  bool player_paused = false;
  pnh.param("player_paused", player_paused, false);
  if (player_paused) {
    ASSERT_TRUE(magcomp::rostest_util::start_replay_when_ready(
        [&] { return collector.subscriber().getNumPublishers() > 0; }, 60.0))
        << "the compensator never came up, or the player has no pause_playback service";
  }
  // Wait for the whole flight (the node flushes its last samples when the bag ends). Under the
  // replay's clock, a pause in the outputs ends the wait only after the bag has reached its last
  // sample, so a node starved of CPU mid-flight is waited for, not taken as samples lost.
  const int year0 = static_cast<int>(f.column("year")[0]),
            doy0 = static_cast<int>(f.column("doy")[0]);
  const ros::Time last_stamp = magcomp::rosio::stamp_of(year0, doy0, f.tt()[f.size() - 1]);
  magcomp::rostest_util::wait_until_settled(
      [&] { return collector.size(); }, static_cast<size_t>(f.size()), 8.0, 200.0, 0.2, {},
      [&] { return magcomp::rostest_util::replay_reached(last_stamp); });
  const std::vector<magcomp::CompensatedField> g_out = collector.outputs();
  ros::WallDuration(1.2).sleep();  // one more diagnostics period after the last output
  for (const char* k : {"scalar_in", "published", "stale_inputs_held", "late_inputs_dropped",
                        "premature_flushes", "gaps", "out_of_order_dropped"}) {
    std::printf("  diagnostics %s = %ld\n", k, diagnostics.count(k));
  }
  if (relay)
    std::printf("  relayed %ld messages with delays up to %.2f s\n", relay->relayed(),
                relay->max_delay_s());
  // Every fluxgate message reached the relay (in another process): the player's publishers
  // outlive the bag, so none queued for TCP is lost at its end.
  if (relay) {
    EXPECT_EQ(relay->relayed(), static_cast<long>(f.size()));
  }
  // Every input in time: a sample computed before its inputs arrived would differ from offline.
  EXPECT_EQ(diagnostics.count("stale_inputs_held"), 0);
  EXPECT_EQ(diagnostics.count("late_inputs_dropped"), 0);
  EXPECT_EQ(diagnostics.count("premature_flushes"), 0);
  ASSERT_EQ(g_out.size(), static_cast<size_t>(f.size())) << "samples lost or duplicated";
  const int year = static_cast<int>(f.column("year")[0]),
            doy = static_cast<int>(f.column("doy")[0]);
  double ss = 0, ss_err = 0;
  long finite = 0, finite_err = 0, error_nan = 0;
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
    ++finite;
    // The live error needs the reference at the sample's stamp (CompensatorRos publishes NaN
    // when the reference topic has not reached it yet, as on a loaded machine): counted apart.
    if (!std::isfinite(o.error_nT)) {
      ++error_nan;
      continue;
    }
    ss_err += std::pow(o.error_nT - (offline[i] - ref[i]), 2);
    ++finite_err;
  }
  const double rms = std::sqrt(ss / finite), rms_err = std::sqrt(ss_err / finite_err);
  std::printf(
      "  %ld samples; online vs offline: rms %.3e nT (live error rms diff %.3e nT; %ld live "
      "errors NaN)\n",
      finite, rms, rms_err, error_nan);
  EXPECT_LT(rms, tol);
  EXPECT_LT(rms_err, tol);
  EXPECT_GT(finite, f.size() - 10);
  EXPECT_LE(error_nan, 10);
}

}  // namespace

int main(int argc, char** argv) {
  return magcomp::rostest_util::run_tests(argc, argv, "test_online_offline", 1);
}
