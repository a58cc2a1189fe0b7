// magcomp: the map-matching navigator online: INS samples and anomaly measurements arrive one
// by one (each on its own stream, the measurements late by the compensator's look-ahead); each
// INS sample becomes a filter step once its measurement is in, or is known missing. ROS-free:
// the navigator node is a thin shell around it. Fed a whole flight it gives run_ekf's numbers.
#pragma once

#include <Eigen/Core>
#include <deque>
#include <map>
#include <memory>
#include <string>
#include <vector>

#include "magcomp/core/nav/ekf.h"
#include "magcomp/core/nav/particle_filter.h"
#include "magcomp/core/nav/streaming_track.h"

namespace magcomp::nav {

/// The navigator's solution at one INS sample.
struct NavigatorOutput {
  double t_s = 0.0;                                               ///< data time, s
  double ins_lat_rad = 0.0, ins_lon_rad = 0.0, ins_alt_m = 0.0;   ///< the INS's position
  double lat_rad = 0.0, lon_rad = 0.0, alt_m = 0.0;               ///< the filter's position
  Eigen::Vector3d velocity_ned_mps = Eigen::Vector3d::Zero();     ///< the filter's velocity
  Eigen::Matrix3d position_cov_ned_m2 = Eigen::Matrix3d::Zero();  ///< north, east, down
  double measurement_nT = NAN, measurement_var_nT2 = NAN;         ///< what the step was given
  double map_nT = NAN, catch_all_nT = NAN;                        ///< at the filter's position
  /// With online calibration: the coefficients after the update and their 1-sigma (model units).
  Eigen::VectorXd coefficients, coefficient_sigma;
  MapMatchingEkf::Step step;
};

/// What the navigator has seen (for diagnostics).
struct NavigatorCounts {
  long ins_in = 0, measurements_in = 0, steps = 0, updates = 0;
  long missing_measurements = 0;  ///< steps without a measurement at their stamp
  long off_map = 0, gated = 0;    ///< steps whose measurement was not used for these reasons
  long nan_measurements = 0;      ///< steps whose measurement was NaN (e.g. a compensator's start)
  long gaps = 0;                  ///< INS gaps (> 1.5 steps): the track restarted
  long out_of_order = 0;          ///< INS samples or measurements older than the last, dropped
  long unmatched_measurements = 0;  ///< measurements no INS sample was stamped at
  long invalid_ins = 0;  ///< INS samples refused: a stamp, position or attitude not finite, a
                         ///< latitude within 0.5 deg of a pole, an altitude off [-12, 100] km
  long invalid_measurements = 0;  ///< measurements refused: a stamp not finite, |value| > 1e6 nT
  long filter_restarts = 0;  ///< the state went non-finite or beyond 1000 km of the INS, or a gap
                             ///< exceeded an hour: restarted from the prior
  long ins_jumps = 0;
  long particle_steps = 0;  ///< steps made by the particle filter (a cold start)  ///< INS samples
                            ///< faster than 2 km/s from the last: the track started again
};

/// Why an INS sample cannot be a filter step ("" when it can): a stamp, position or attitude
/// that is not finite, a latitude within 0.5 deg of a pole (the north/east frame is singular
/// there), an altitude outside [-12, 100] km. The navigator node and `magcomp navigate` both
/// refuse such samples and count them.
std::string invalid_ins_reason(const InsSample& s);

class StreamingNavigator {
 public:
  /// INS samples every dt_s (s); the filter's settings; `map` must outlive the navigator. With
  /// `cold_start`, the first steps run a particle filter (particle_filter.h) until its cloud has
  /// gathered, then the EKF starts where it ended (and again after each restart).
  StreamingNavigator(const AnomalyMap& map, const FilterSettings& settings, double dt_s,
                     const ParticleSettings* cold_start = nullptr);
  /// Data time (s) the particle filter handed over to the EKF (NaN: not yet, or none).
  double handover_t_s() const { return handover_t_s_; }
  /// Whether the particle filter is running.
  bool in_cold_start() const { return pf_active_; }
  /// The next INS sample (data time increasing; one refused by invalid_ins_reason is counted and
  /// dropped, so its stamp becomes a gap). Returns the steps it made possible.
  std::vector<NavigatorOutput> push_ins(const InsSample& s);
  /// The anomaly measured at data time t_s (nT) and its variance (nT^2; NaN: the settings' R).
  /// A value that is not finite or beyond 1e6 nT is no measurement (its step goes without one,
  /// counted). Returns the steps it made possible. Every output is finite: a state that goes
  /// non-finite restarts the filter (counted), never reaches the caller. With online
  /// calibration the anomaly is the raw one and `columns` the model's columns at t_s.
  std::vector<NavigatorOutput> push_measurement(double t_s, double anomaly_nT, double variance_nT2,
                                                const Eigen::VectorXd* columns = nullptr);
  /// The INS stream ended: its last two samples wait for their measurements like the others.
  std::vector<NavigatorOutput> end_of_ins();
  /// Steps every INS sample still waiting, those without a measurement without one (the
  /// measurement source stalled, or the stream is over).
  std::vector<NavigatorOutput> flush();
  /// INS samples held (in the track and waiting for their measurement).
  size_t pending() const { return track_.pending() + waiting_.size(); }
  const NavigatorCounts& counts() const { return counts_; }
  /// With online calibration: the coefficients' covariance after the last update (k x k).
  Eigen::MatrixXd coefficient_covariance() const;
  /// Back to the start: a new flight (time jumped back).
  void reset();

 private:
  std::vector<NavigatorOutput> drain(bool force);
  // A measurement waiting for its INS sample.
  struct Measurement {
    double z_nT = NAN, var_nT2 = NAN;
    Eigen::VectorXd columns;  // online calibration's model columns (empty: none)
  };
  NavigatorOutput run_step(const TrackPoint& p, const Measurement& m, bool missing);
  // The filter's step at p with measurement m (z NaN: none) and what it gives.
  NavigatorOutput step_output(const TrackPoint& p, const Measurement& m);
  // The same from the particle filter, handing over to the EKF when its cloud has gathered.
  NavigatorOutput particle_output(const TrackPoint& p, const Measurement& m);

  const AnomalyMap& map_;
  FilterSettings settings_;
  double dt_s_;
  MapMatchingEkf ekf_;
  StreamingTrack track_;
  std::deque<TrackPoint> waiting_;              // track points waiting for their measurement
  std::map<double, Measurement> measurements_;  // by stamp
  double last_ins_t_ = NAN, last_meas_t_ = NAN, last_step_t_ = NAN;
  TrackPoint last_point_;
  InsSample last_ins_;
  std::unique_ptr<ParticleFilter> pf_;
  bool pf_active_ = false;
  double handover_t_s_ = NAN, first_step_t_s_ = NAN;
  NavigatorCounts counts_;
};

}  // namespace magcomp::nav
