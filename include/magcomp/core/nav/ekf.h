// magcomp: map-matching navigation: an error-state extended Kalman filter on the INS (18 states:
// the Pinson errors of pinson.h and a FOGM catch-all in nT), the measurement being the anomaly
// map at the corrected position plus the catch-all; and the Cramér-Rao bound about a trajectory.
// Equal to MagNav.jl's ekf and crlb (test: its published vectors).
#pragma once

#include <Eigen/Core>
#include <cmath>
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
  double qd_step_s = NAN;  ///< the step qd is for, s (NaN: unknown; a gap then adds one qd)
  double r_nT2 = 1.0;
  /// Add the map's representation error to each measurement's R
  /// (AnomalyMap::representation_var_nT2: the interpolation's error and the linearisation over the
  /// position's covariance; the bound takes the interpolation's alone). false: R as given
  /// (MagNav.jl's filter).
  bool map_representation_var = false;
  ErrorModelTaus taus;
  /// A measurement whose normalised innovation squared (innovation^2 / its variance) exceeds this
  /// is not used (chi-square, 1 dof: 10.83 rejects 0.1 % of consistent ones); infinite: none.
  double nis_gate = INFINITY;
  /// Remove a constant offset from every measurement: the first usable measurement minus the map
  /// at the INS position (a band-pass fit cannot see the aircraft's constant field, hundreds of
  /// nT, and a zero-mean catch-all would pull it into the position). false: none (MagNav.jl).
  bool offset_from_first = false;
  /// Online calibration (empty c0: none). The compensation model's k coefficients become
  /// random-walk states after the 18 navigation states (all of a model's terms are linear in
  /// them); the measurement is then the raw anomaly (the realigned scalar less the IGRF and the
  /// diurnal) and predicts map + catch-all + a.c, with a the model's k columns at the sample.
  Eigen::VectorXd c0;        ///< prior coefficients (the model's units)
  Eigen::MatrixXd pc0;       ///< their prior covariance (k x k)
  Eigen::VectorXd qc_per_s;  ///< their random-walk variance growth per second (k)
  /// The number of states: 18, plus the coefficients.
  Eigen::Index states() const { return 18 + c0.size(); }
};

/// The filter's output at each sample, after its measurement update: the error state (18) and
/// its covariance; the innovation (nT; NaN where the measurement was not used: missing, or off
/// the map, or gated) and its variance (nT^2).
struct FilterResult {
  Eigen::MatrixXd x;               ///< 18 x N
  std::vector<Eigen::MatrixXd> p;  ///< N of 18 x 18
  Eigen::VectorXd innovation_nT, innovation_var_nT2;
};

/// The filter one sample at a time (what run_ekf does over a track, and a node does online).
class MapMatchingEkf {
 public:
  /// What one step did with its measurement.
  struct Step {
    double innovation_nT = NAN;       ///< measurement - predicted (map + catch-all), nT
    double innovation_var_nT2 = NAN;  ///< its predicted variance, nT^2
    bool updated = false;             ///< the measurement was used
    bool gated = false;               ///< it was rejected by the NIS gate
    bool on_map = true;               ///< the corrected position lies on a valid map cell
  };
  /// `map` must outlive the filter. Throws magcomp::Error on settings of the wrong size.
  MapMatchingEkf(const AnomalyMap& map, const FilterSettings& settings);
  /// The measurement update at INS sample `p` (position lat, lon in rad; anomaly in nT, NaN for
  /// none; its noise variance r_nT2 > 0, NaN: the settings' R), then the propagation over dt_s
  /// to the next sample. Off the map the measurement is not used. With online calibration the
  /// anomaly is the raw one and `columns` the model's k columns at the sample (none, or one not
  /// finite: the measurement is not used).
  Step step(const NavPoint& p, double lat_rad, double lon_rad, double anomaly_nT, double r_nT2,
            double dt_s, const Eigen::VectorXd* columns = nullptr);
  /// The error state (18, then the coefficients) and covariance after the last step's update
  /// (before propagation).
  const Eigen::VectorXd& x_post() const { return x_post_; }
  const Eigen::MatrixXd& p_post() const { return p_post_; }
  /// Propagation only, over dt_s (a gap in the INS samples).
  void propagate(const NavPoint& p, double dt_s);
  /// The constant offset removed from the measurements, nT (0 until set, or without it).
  double offset_nT() const { return std::isfinite(offset_nT_) ? offset_nT_ : 0.0; }
  /// Back to the initial state and covariance.
  void reset();
  /// Back to the initial state, then the position error at (dlat, dlon) rad with covariance
  /// p_rad2 (2 x 2, rad^2) and the measurements' constant offset `offset_nT`: a start handed over
  /// by the particle filter.
  void start_at(double dlat_rad, double dlon_rad, const Eigen::Matrix2d& p_rad2, double offset_nT);

 private:
  void propagate_by(const NavPoint& p, double dt_s, double q_scale);

  const AnomalyMap& map_;
  FilterSettings s_;
  Eigen::VectorXd x_, x_post_;
  Eigen::MatrixXd p_, p_post_;
  double offset_nT_ = NAN;  // the measurements' constant offset (offset_from_first)
};

/// Runs the filter over an INS track with one scalar anomaly measurement per sample (nT); a NaN
/// measurement is skipped (the state is only propagated; its innovation is NaN), and so is one
/// whose corrected position is off the map.
/// `r_nT2`, when given, is each sample's measurement variance (NaN: the settings' R).
FilterResult run_ekf(const NavTrack& ins, const Eigen::VectorXd& anomaly_nT, const AnomalyMap& map,
                     const FilterSettings& settings, const Eigen::VectorXd* r_nT2 = nullptr);

/// The Cramér-Rao lower bound about the true trajectory: the covariance after each update.
std::vector<Eigen::MatrixXd> crlb(const NavTrack& truth, const AnomalyMap& map,
                                  const FilterSettings& settings);

}  // namespace magcomp::nav
