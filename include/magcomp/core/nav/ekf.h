// magcomp: map-matching navigation: an error-state extended Kalman filter on the INS (18 states:
// the Pinson errors of pinson.h and a FOGM catch-all in nT), the measurement being the anomaly
// map at the corrected position plus the catch-all; and the Cramér-Rao bound about a trajectory.
// Equal to MagNav.jl's ekf and crlb (test: its published vectors).
#pragma once

#include <Eigen/Core>
#include <vector>

#include "magcomp/core/nav/anomaly_map.h"
#include "magcomp/core/nav/pinson.h"

namespace magcomp::nav {

/// A navigation solution sampled every dt_s: position (rad, rad, m), velocity (NED, m/s),
/// specific force (NED, m/s^2), attitude (body to NED).
struct NavTrack {
  double dt_s = 1.0;
  Eigen::VectorXd lat_rad, lon_rad, alt_m, vn_mps, ve_mps, vd_mps, fn_mps2, fe_mps2, fd_mps2;
  std::vector<Eigen::Matrix3d> cnb;
  Eigen::Index size() const { return lat_rad.size(); }
  NavPoint point(Eigen::Index t) const;
};

/// Filter settings: initial covariance, discrete process noise (18 x 18), measurement noise
/// variance (nT^2), the error model's time constants.
struct FilterSettings {
  Eigen::MatrixXd p0, qd;
  double r_nT2 = 1.0;
  ErrorModelTaus taus;
};

/// The filter's output at each sample, after its measurement update: the error state (18) and
/// its covariance; the innovation (nT) and its variance (nT^2).
struct FilterResult {
  Eigen::MatrixXd x;               ///< 18 x N
  std::vector<Eigen::MatrixXd> p;  ///< N of 18 x 18
  Eigen::VectorXd innovation_nT, innovation_var_nT2;
};

/// Runs the filter over an INS track with one scalar anomaly measurement per sample (nT); a NaN
/// measurement is skipped (the state is only propagated; its innovation is NaN).
FilterResult run_ekf(const NavTrack& ins, const Eigen::VectorXd& anomaly_nT, const AnomalyMap& map,
                     const FilterSettings& settings);

/// The Cramér-Rao lower bound about the true trajectory: the covariance after each update.
std::vector<Eigen::MatrixXd> crlb(const NavTrack& truth, const AnomalyMap& map,
                                  const FilterSettings& settings);

}  // namespace magcomp::nav
