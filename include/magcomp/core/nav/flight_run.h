// magcomp: a recorded flight navigated row by row through the StreamingNavigator (the node's own
// path, so a NaN, a gap, a duplicated stamp or a pole is handled offline exactly as online), and
// scored against its true track: the DRMS of the filter, of the INS alone and of the Cramér-Rao
// bound, the NEES, the innovations, and every input fault counted.
#pragma once

#include <Eigen/Core>
#include <vector>

#include "magcomp/core/nav/anomaly_map.h"
#include "magcomp/core/nav/flight_navigation.h"
#include "magcomp/core/nav/streaming_navigator.h"

namespace magcomp::nav {

/// One run of the navigator over a flight: its steps in time order, the flight row of each, and
/// the navigator's counts (INS samples refused, gaps, duplicated stamps, measurements off the
/// map, NaN, gated or refused).
struct FlightRun {
  std::vector<NavigatorOutput> steps;
  std::vector<Eigen::Index> rows;
  NavigatorCounts counts;
  Eigen::MatrixXd coefficient_covariance;  ///< online calibration: at the end (k x k)
  double handover_t_s = NAN;  ///< a cold start: when the particle filter handed over (NaN: never)
};

/// Feeds each row's INS sample and then its measurement (anomaly_nT, NaN: none; var_nT2, when
/// given, its variance in nT^2; columns, with online calibration, the model's columns: one row
/// per flight row) to a StreamingNavigator (a particle filter first with `cold_start`), and
/// flushes it at the end.
FlightRun run_flight(const std::vector<InsSample>& ins, const Eigen::VectorXd& anomaly_nT,
                     const Eigen::VectorXd* var_nT2, const AnomalyMap& map,
                     const FilterSettings& settings, double dt_s,
                     const Eigen::MatrixXd* columns = nullptr,
                     const ParticleSettings* cold_start = nullptr);

/// The Cramér-Rao bound along the true track: the filter run on the truth as its INS, measuring
/// the map's own value wherever the map covers the position (never a map extrapolated off its
/// grid), with no offset and no gate; its covariance is the bound.
FlightRun crlb_run(const std::vector<InsSample>& truth, const AnomalyMap& map,
                   FilterSettings settings, double dt_s);

/// The navigation filter's position at each row (rad; NaN where no step was made), run with its
/// default settings (nav_model.h) and the first measurement's offset removed, on `anomaly_nT`:
/// where a flight is, when neither a GPS nor a stinger is trusted.
struct TrackPositions {
  Eigen::VectorXd lat_rad, lon_rad;
};
TrackPositions filter_positions(const FlightData& flight, const Eigen::VectorXd& anomaly_nT,
                                const AnomalyMap& map);

/// The figures of a run against the truth. A figure with nothing to compute it from is NaN, and
/// each says how many samples it comes from.
struct NavigationScores {
  long rows = 0;           ///< flight rows
  long scored = 0;         ///< steps whose true position is valid: the DRMS and NEES samples
  long updates = 0;        ///< measurements the filter used
  long invalid_truth = 0;  ///< rows whose true position or attitude was refused
  long map_compared = 0;   ///< samples of measurement_minus_map_std_nT
  double measurement_minus_map_std_nT = NAN;  ///< at the true position, nT
  double drms_filter_m = NAN, drms_ins_m = NAN, drms_crlb_m = NAN;
  /// Shares of the scored steps whose horizontal NEES lies in its 95 % bounds, and above them
  /// (the filter overconfident).
  double nees_in_bounds = NAN, nees_above = NAN;
  double innovation_mean_nT = NAN, innovation_std_nT = NAN, nis_mean = NAN;
  NavigatorCounts counts;  ///< the run's
};

/// Scores `run` (and its bound `crlb`) against the samples' true track.
NavigationScores score_run(const FlightRun& run, const FlightRun& crlb,
                           const FlightSamples& samples, const Eigen::VectorXd& anomaly_nT,
                           const AnomalyMap& map);

}  // namespace magcomp::nav
