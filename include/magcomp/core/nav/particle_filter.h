// magcomp: a start far from the truth. The EKF linearises the map about its position, so it
// needs a start within a fraction of the map's correlation length; kilometres off it locks onto
// a wrong hill. A Rao-Blackwellised (marginalised) particle filter covers that start: particles
// over the horizontal error of the INS position (north, east, m), each carrying a Kalman filter
// of the one state that is linear-Gaussian given the position, the measurement's constant
// offset (the aircraft's constant field and the map's level, nT). When the cloud has gathered
// (its horizontal 1-sigma below a threshold) the navigator hands over to the EKF.
#pragma once

#include <Eigen/Core>
#include <random>
#include <vector>

#include "magcomp/core/nav/anomaly_map.h"

namespace magcomp::nav {

struct ParticleSettings {
  int particles = 20000;
  double init_sigma_m = 2000.0;    ///< the start's horizontal 1-sigma, m
  double walk_m_per_sqrt_s = 0.5;  ///< the INS error's random walk, m per sqrt(s)
  double offset_sigma_nT = 500.0;  ///< the measurement offset's prior 1-sigma, nT
  double handover_sigma_m = 30.0;  ///< hand over when the cloud's horizontal 1-sigma is below
  unsigned seed = 1;
};

/// The cloud's summary: mean horizontal error of the INS (north, east, m), its covariance (m^2),
/// the measurement offset (nT) and whether the cloud has gathered.
struct ParticleEstimate {
  Eigen::Vector2d offset_m = Eigen::Vector2d::Zero();
  Eigen::Matrix2d covariance_m2 = Eigen::Matrix2d::Zero();
  double measurement_offset_nT = 0.0, measurement_offset_var_nT2 = 0.0;
  double effective_particles = 0.0;
  bool gathered = false;
};

class ParticleFilter {
 public:
  /// `map` must outlive the filter. Throws magcomp::Error on settings out of range.
  ParticleFilter(const AnomalyMap& map, const ParticleSettings& settings);
  /// One sample: the INS position (rad), the anomaly measured (nT; NaN: none) and its noise
  /// variance (nT^2), the time since the last step (s). Particles off the map weigh little.
  void step(double lat_rad, double lon_rad, double anomaly_nT, double r_nT2, double dt_s);
  ParticleEstimate estimate() const;
  void reset();

 private:
  void resample();

  const AnomalyMap& map_;
  ParticleSettings s_;
  std::mt19937_64 rng_;
  std::vector<Eigen::Vector2d> offset_;  // north, east, m
  std::vector<double> bias_, bias_var_, log_w_;
  double walk_s_ = 0.0;  // time the walk has not been drawn for, s
};

}  // namespace magcomp::nav
