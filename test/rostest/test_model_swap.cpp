// rostest: swapping the model file mid-replay switches the live output from the old model's
// offline values to the new model's at one stamp, with no sample lost; also with the aux
// channels relayed late (model_swap_delayed.test).
#include <gtest/gtest.h>
#include <magcomp/AuxChannels.h>
#include <magcomp/CompensatedField.h>
#include <ros/ros.h>

#include <cmath>
#include <cstdio>
#include <fstream>
#include <memory>
#include <mutex>

#include "magcomp/core/apply/apply.h"
#include "magcomp/core/model/model.h"
#include "magcomp/ros/bag_converter.h"
#include "rostest_util.h"

namespace {

void copy_atomically(const std::string& from, const std::string& to) {
  {
    std::ifstream in(from, std::ios::binary);
    std::ofstream out(to + ".tmp", std::ios::binary);
    out << in.rdbuf();
  }
  std::rename((to + ".tmp").c_str(), to.c_str());
}

TEST(ModelSwap, TakesEffectAtOneStampWithNoSampleLost) {
  ros::NodeHandle nh, pnh("~");
  std::string h5, old_path, new_path, live;
  ASSERT_TRUE(pnh.getParam("h5", h5));
  ASSERT_TRUE(pnh.getParam("old_model", old_path));
  ASSERT_TRUE(pnh.getParam("new_model", new_path));
  ASSERT_TRUE(pnh.getParam("live_model", live));
  const magcomp::FlightData f = magcomp::read_flight_h5(h5);
  const Eigen::VectorXd off_old = magcomp::compensate(magcomp::load_model_yaml(old_path), f);
  const Eigen::VectorXd off_new = magcomp::compensate(magcomp::load_model_yaml(new_path), f);
  const auto ref = f.column("mag_1_c");
  // Fault injection (model_swap_delayed.test): the aux channels reach the compensator through
  // this node, each after a random wall delay of up to relay_max_delay_s, in order. The new
  // model reads an aux channel and the old one none, so at the swap the aux messages lag the
  // scalar samples the old model has already compensated.
  const auto relay = magcomp::rostest_util::relay_from_params<magcomp::AuxChannels>(nh, pnh, 11u);
  // Start every run from the TL-only model (the node picks the file up within 0.25 s, before the
  // bag starts playing 4 s after launch).
  copy_atomically(old_path, live);
  ros::WallDuration(1.0).sleep();
  magcomp::rostest_util::OutputCollector collector(nh);
  bool swapped = false;
  magcomp::rostest_util::wait_until_settled(
      [&] { return collector.size(); }, static_cast<size_t>(f.size()), 8.0, 200.0, 0.05,
      [&](size_t n) {
        if (!swapped && n > static_cast<size_t>(f.size() / 2)) {
          copy_atomically(new_path, live);  // as `magcomp calibrate --out` does: temp + rename
          swapped = true;
        }
      },
      [&] {
        return magcomp::rostest_util::replay_reached(
            magcomp::rosio::stamp_of(static_cast<int>(f.column("year")[0]),
                                     static_cast<int>(f.column("doy")[0]), f.tt()[f.size() - 1]));
      });
  const std::vector<magcomp::CompensatedField> g_out = collector.outputs();
  if (relay) {
    std::printf("  relayed %ld aux messages with delays up to %.2f s\n", relay->relayed(),
                relay->max_delay_s());
    EXPECT_EQ(relay->relayed(), static_cast<long>(f.size()));
  }
  ASSERT_TRUE(swapped);
  ASSERT_EQ(g_out.size(), static_cast<size_t>(f.size())) << "samples lost or duplicated";
  // Each output equals the old model's offline value, then (from one index on) the new model's.
  Eigen::Index switch_at = -1;
  long mismatches = 0;
  double ss_err = 0;
  long n_after = 0;
  for (Eigen::Index i = 0; i < f.size(); ++i) {
    const double v = g_out[static_cast<size_t>(i)].compensated_nT;
    if (!std::isfinite(v) || !std::isfinite(off_old[i]) || !std::isfinite(off_new[i])) continue;
    const bool is_old = std::abs(v - off_old[i]) < 1e-6, is_new = std::abs(v - off_new[i]) < 1e-6;
    if (switch_at < 0 && is_new && !is_old) switch_at = i;
    if (switch_at < 0 ? !is_old : !is_new) {
      // Which sample, and what it holds: a rare mismatch says where the swap went wrong.
      if (++mismatches <= 5)
        std::printf(
            "  mismatch at sample %ld (t = %.1f s, %s the swap): measured %.6f, correction "
            "%.6f, compensated %.6f nT; offline old %.6f, new %.6f nT\n",
            static_cast<long>(i), f.tt()[i] - f.tt()[0], switch_at < 0 ? "before" : "after",
            g_out[static_cast<size_t>(i)].measured_nT,
            g_out[static_cast<size_t>(i)].aircraft_correction_nT, v, off_old[i], off_new[i]);
    }
    if (switch_at >= 0) {
      ss_err += std::pow(g_out[static_cast<size_t>(i)].error_nT - (off_new[i] - ref[i]), 2);
      ++n_after;
    }
  }
  std::printf(
      "  swap took effect at sample %ld of %ld (t = %.1f s); %ld after it, live error rms diff "
      "%.2e nT\n",
      static_cast<long>(switch_at), static_cast<long>(f.size()),
      switch_at >= 0 ? f.tt()[switch_at] - f.tt()[0] : -1.0, n_after,
      n_after ? std::sqrt(ss_err / n_after) : -1.0);
  EXPECT_GT(switch_at, f.size() / 2);
  EXPECT_EQ(mismatches, 0);
  ASSERT_GT(n_after, 100);
  EXPECT_LT(std::sqrt(ss_err / n_after), 1e-6);
}

}  // namespace

int main(int argc, char** argv) {
  return magcomp::rostest_util::run_tests(argc, argv, "test_model_swap", 1);
}
