// magcomp ROS layer: the navigator's diagnostics: its state and every input fault counted (see
// navigator_ros.h).
#include "magcomp/ros/navigator_ros.h"

#include <geometry_msgs/PoseWithCovarianceStamped.h>
#include <magcomp/NavigationStatus.h>
#include <nav_msgs/OccupancyGrid.h>
#include <nav_msgs/Odometry.h>

#include <algorithm>
#include <cmath>
#include <set>

#include "magcomp/core/error.h"
#include "magcomp/core/geo/attitude.h"
#include "magcomp/core/math/constants.h"
#include "magcomp/core/nav/nav_model.h"
#include "magcomp/core/nav/online_calibration.h"
#include "magcomp/ros/callback_guard.h"
#include "magcomp/ros/diagnostic_counts.h"
#include "magcomp/ros/params.h"

namespace magcomp::rosio {
namespace {

constexpr long kOffMapWarnSteps = 10;  // consecutive steps off the map: a warning

}  // namespace

void NavigatorRos::diagnose(diagnostic_updater::DiagnosticStatusWrapper& stat) {
  const nav::NavigatorCounts c = nav_ ? nav_->counts() : nav::NavigatorCounts{};
  stat.add("map_path", map_path_);
  const long faults =
      add_counts(stat, {{"ins_samples_in", c.ins_in},
                        {"measurements_in", c.measurements_in},
                        {"steps", c.steps},
                        {"published", published_},
                        {"updates", c.updates},
                        {"missing_measurements", c.missing_measurements, true},
                        {"unmatched_measurements_dropped", c.unmatched_measurements},
                        {"off_map_measurements", c.off_map},
                        {"gated_measurements", c.gated},
                        {"nan_measurements", c.nan_measurements},
                        {"ins_gaps", c.gaps, true},
                        {"out_of_order_dropped", c.out_of_order, true},
                        {"time_jumps_back", jumps_back_, true},
                        {"nan_inputs", nan_inputs_, true},
                        {"imu_without_fix_dropped", ins_pairs_.counts().second_dropped},
                        {"fix_without_imu_dropped", ins_pairs_.counts().first_dropped},
                        {"ins_no_fix_dropped", ins_no_fix_, true},
                        {"ins_refused", ins_refused_ + c.invalid_ins, true},
                        {"measurements_refused", c.invalid_measurements, true},
                        {"filter_restarts", c.filter_restarts, true},
                        {"ins_jumps", c.ins_jumps, true},
                        {"stamps_out_of_range", bad_stamps_, true},
                        {"callback_errors", callback_errors_}});
  if (consecutive_off_map_ >= kOffMapWarnSteps) {
    stat.summary(diagnostic_msgs::DiagnosticStatus::WARN,
                 "off the map: navigating on the INS alone");
  } else if (callback_errors_ > 0) {
    stat.summary(diagnostic_msgs::DiagnosticStatus::ERROR,
                 "messages dropped on an internal error (see callback_errors)");
  } else if (faults > 0) {
    stat.summary(diagnostic_msgs::DiagnosticStatus::WARN,
                 "running; input faults seen (see counts)");
  } else {
    stat.summary(diagnostic_msgs::DiagnosticStatus::OK, "running");
  }
  if (cold_start_) {
    stat.add("cold_start_particle_steps", c.particle_steps);
    stat.add("cold_start_handed_over", nav_ && !nav_->in_cold_start());
  }
  if (online_) {
    stat.add("online_columns_mismatched", columns_mismatched_);
    stat.add("online_halves_waiting", static_cast<long>(online_pairs_.waiting()));
    stat.add("online_halves_dropped",
             online_pairs_.counts().first_dropped + online_pairs_.counts().second_dropped);
  }
  stat.add("pending", nav_ ? static_cast<long>(nav_->pending()) : 0L);
  if (nis_n_ > 0) stat.add("nis_mean", nis_sum_ / static_cast<double>(nis_n_));
  stat.add("on_map", last_ ? last_->step.on_map : false);
  if (last_) {
    stat.add("last_innovation_nT", last_->step.innovation_nT);
    stat.add("sigma_horizontal_m",
             std::sqrt(last_->position_cov_ned_m2(0, 0) + last_->position_cov_ned_m2(1, 1)));
  }
}

}  // namespace magcomp::rosio
