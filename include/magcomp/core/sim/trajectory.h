// magcomp simulator: flight-plan kinematics (attitude, rates, velocities, positions).
#pragma once

#include <Eigen/Core>

#include "magcomp/core/sim/scenario.h"

namespace magcomp::sim {

/// The aircraft's state at every sample. Angles in rad (yaw clockwise from north, pitch nose up,
/// roll right wing down), positions in m in a local north-east frame around the origin.
struct Track {
  Eigen::VectorXd t_s, line;
  Eigen::VectorXd yaw_rad, pitch_rad, roll_rad;
  Eigen::VectorXd north_m, east_m, alt_m;  ///< alt: above the WGS-84 ellipsoid
  Eigen::VectorXd vn_mps, ve_mps, vu_mps, speed_mps;
  Eigen::VectorXd lat_deg, lon_deg;
  Eigen::VectorXd maneuver;  ///< 0 none, 1 pitch, 2 roll, 3 yaw (calibration maneuvers)
  Eigen::Index size() const { return t_s.size(); }
};

/// Integrates the scenario's flight plan at the scenario's sample rate. Deterministic in the seed.
Track fly(const Scenario& scenario);

}  // namespace magcomp::sim
