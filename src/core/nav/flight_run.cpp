// magcomp: a recorded flight through the streaming navigator, and its scores (flight_run.h).
#include "magcomp/core/nav/flight_run.h"

#include <Eigen/Dense>
#include <algorithm>
#include <cmath>
#include <limits>

#include "magcomp/core/error.h"
#include "magcomp/core/nav/nav_model.h"

namespace magcomp::nav {
namespace {

// 95 % bounds of a chi-square with 2 degrees of freedom (one sample): the horizontal NEES.
constexpr double kNees2Low = 0.0506356, kNees2High = 7.37776;

// The row each step belongs to: the first row stamped at its time (rows in time order; a
// duplicated stamp's later rows were refused as out of order).
void attach_rows(const std::vector<InsSample>& rows, FlightRun* run) {
  run->rows.clear();
  for (const NavigatorOutput& o : run->steps) {
    const auto it = std::lower_bound(rows.begin(), rows.end(), o.t_s,
                                     [](const InsSample& s, double t) { return s.t_s < t; });
    run->rows.push_back(static_cast<Eigen::Index>(it - rows.begin()));
  }
}

void take(std::vector<NavigatorOutput>&& steps, FlightRun* run) {
  for (NavigatorOutput& o : steps) run->steps.push_back(std::move(o));
}

}  // namespace

FlightRun run_flight(const std::vector<InsSample>& ins, const Eigen::VectorXd& anomaly_nT,
                     const Eigen::VectorXd* var_nT2, const AnomalyMap& map,
                     const FilterSettings& settings, double dt_s, const Eigen::MatrixXd* columns,
                     const ParticleSettings* cold_start) {
  StreamingNavigator nav(map, settings, dt_s, cold_start);
  FlightRun run;
  run.steps.reserve(ins.size());
  Eigen::VectorXd row;
  for (size_t k = 0; k < ins.size(); ++k) {
    const auto i = static_cast<Eigen::Index>(k);
    take(nav.push_ins(ins[k]), &run);
    if (columns) row = columns->row(i).transpose();
    take(nav.push_measurement(ins[k].t_s, anomaly_nT[i], var_nT2 ? (*var_nT2)[i] : NAN,
                              columns ? &row : nullptr),
         &run);
  }
  take(nav.end_of_ins(), &run);
  take(nav.flush(), &run);
  run.counts = nav.counts();
  if (settings.c0.size() > 0) run.coefficient_covariance = nav.coefficient_covariance();
  run.handover_t_s = nav.handover_t_s();
  attach_rows(ins, &run);
  return run;
}

FlightRun crlb_run(const std::vector<InsSample>& truth, const AnomalyMap& map,
                   FilterSettings settings, double dt_s) {
  settings.offset_from_first = false;
  settings.nis_gate = INFINITY;
  Eigen::VectorXd z(static_cast<Eigen::Index>(truth.size()));
  for (size_t k = 0; k < truth.size(); ++k) {
    const InsSample& s = truth[k];
    z[static_cast<Eigen::Index>(k)] =
        invalid_ins_reason(s).empty() && map.covers(s.lat_rad, s.lon_rad)
            ? map.value(s.lat_rad, s.lon_rad)
            : NAN;
  }
  return run_flight(truth, z, nullptr, map, settings, dt_s);
}

TrackPositions filter_positions(const FlightData& flight, const Eigen::VectorXd& anomaly_nT,
                                const AnomalyMap& map) {
  const FlightSamples s = flight_samples(flight);
  double lat1 = NAN;
  for (const InsSample& x : s.ins)
    if (invalid_ins_reason(x).empty()) {
      lat1 = x.lat_rad;
      break;
    }
  if (!std::isfinite(lat1))
    throw Error(flight.source() + ": no INS sample is usable: no filter track");
  FilterSettings settings = filter_model(s.dt_s, lat1, ModelSigmas{});
  settings.offset_from_first = true;
  const FlightRun run = run_flight(s.ins, anomaly_nT, nullptr, map, settings, s.dt_s);
  TrackPositions p;
  p.lat_rad = Eigen::VectorXd::Constant(flight.size(), NAN);
  p.lon_rad = Eigen::VectorXd::Constant(flight.size(), NAN);
  for (size_t k = 0; k < run.steps.size(); ++k) {
    p.lat_rad[run.rows[k]] = run.steps[k].lat_rad;
    p.lon_rad[run.rows[k]] = run.steps[k].lon_rad;
  }
  return p;
}

NavigationScores score_run(const FlightRun& run, const FlightRun& crlb,
                           const FlightSamples& samples, const Eigen::VectorXd& anomaly_nT,
                           const AnomalyMap& map) {
  NavigationScores s;
  s.rows = static_cast<long>(samples.truth.size());
  s.counts = run.counts;
  s.updates = run.counts.updates;
  std::vector<bool> truth_ok(samples.truth.size());
  double sum = 0, sum2 = 0;
  for (size_t k = 0; k < samples.truth.size(); ++k) {
    const InsSample& t = samples.truth[k];
    truth_ok[k] = invalid_ins_reason(t).empty();
    s.invalid_truth += !truth_ok[k];
    if (!truth_ok[k] || !map.covers(t.lat_rad, t.lon_rad)) continue;
    const double d = anomaly_nT[static_cast<Eigen::Index>(k)] - map.value(t.lat_rad, t.lon_rad);
    if (!std::isfinite(d)) continue;
    sum += d;
    sum2 += d * d;
    ++s.map_compared;
  }
  if (s.map_compared > 1) {
    const double n = static_cast<double>(s.map_compared), mean = sum / n;
    s.measurement_minus_map_std_nT = std::sqrt(std::max(0.0, sum2 / n - mean * mean));
  }
  double ss_filter = 0, ss_ins = 0, nis = 0, innovation = 0, innovation2 = 0;
  long inside = 0, above = 0, used = 0;
  for (size_t k = 0; k < run.steps.size(); ++k) {
    const NavigatorOutput& o = run.steps[k];
    if (o.step.updated && std::isfinite(o.step.innovation_nT)) {
      const double v = o.step.innovation_nT;
      nis += v * v / o.step.innovation_var_nT2;
      innovation += v;
      innovation2 += v * v;
      ++used;
    }
    const auto row = static_cast<size_t>(run.rows[k]);
    if (row >= truth_ok.size() || !truth_ok[row]) continue;
    const InsSample& t = samples.truth[row];
    const Eigen::Vector2d err(dlat_to_north_m(o.lat_rad - t.lat_rad, t.lat_rad),
                              dlon_to_east_m(o.lon_rad - t.lon_rad, t.lat_rad));
    ss_filter += err.squaredNorm();
    ss_ins += std::pow(dlat_to_north_m(o.ins_lat_rad - t.lat_rad, t.lat_rad), 2) +
              std::pow(dlon_to_east_m(o.ins_lon_rad - t.lon_rad, t.lat_rad), 2);
    const Eigen::Matrix2d c = o.position_cov_ned_m2.topLeftCorner<2, 2>();
    const double nees = err.dot(c.ldlt().solve(err));
    inside += nees >= kNees2Low && nees <= kNees2High;
    above += nees > kNees2High;
    ++s.scored;
  }
  if (s.scored > 0) {
    const double n = static_cast<double>(s.scored);
    s.drms_filter_m = std::sqrt(ss_filter / n);
    s.drms_ins_m = std::sqrt(ss_ins / n);
    s.nees_in_bounds = static_cast<double>(inside) / n;
    s.nees_above = static_cast<double>(above) / n;
  }
  if (used > 0) {
    const double n = static_cast<double>(used);
    s.innovation_mean_nT = innovation / n;
    s.nis_mean = nis / n;
    if (used > 1)
      s.innovation_std_nT =
          std::sqrt(std::max(0.0, innovation2 / n - s.innovation_mean_nT * s.innovation_mean_nT));
  }
  double ss_bound = 0;
  long bound_n = 0;
  for (const NavigatorOutput& o : crlb.steps) {
    ss_bound += o.position_cov_ned_m2(0, 0) + o.position_cov_ned_m2(1, 1);
    ++bound_n;
  }
  if (bound_n > 0) s.drms_crlb_m = std::sqrt(ss_bound / static_cast<double>(bound_n));
  return s;
}

}  // namespace magcomp::nav
