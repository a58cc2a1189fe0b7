// magcomp navigate: the compensated anomaly steers the map-matching EKF; the compensation scored
// in metres (DRMS of the filter, of the INS alone and of the Cramér-Rao bound) beside nT.
#include <Eigen/Dense>
#include <algorithm>
#include <cmath>
#include <cstdio>
#include <nlohmann/json.hpp>
#include <optional>

#include "common.h"
#include "magcomp/core/error.h"
#include "magcomp/core/io/file_io.h"
#include "magcomp/core/io/h5_array.h"
#include "magcomp/core/io/output_guard.h"
#include "magcomp/core/math/constants.h"
#include "magcomp/core/model/model.h"
#include "magcomp/core/nav/anomaly_map.h"
#include "magcomp/core/nav/ekf.h"
#include "magcomp/core/nav/flight_navigation.h"
#include "magcomp/core/nav/flight_run.h"
#include "magcomp/core/nav/nav_model.h"
#include "magcomp/core/nav/online_calibration.h"
#include "navigate_report.h"
#include "subcommands.h"

namespace magcomp::cli {
namespace {

nlohmann::json to_json(const nav::NavigationScores& s) {
  const nav::NavigatorCounts& c = s.counts;
  return {{"measurement_minus_map_std_nT", json_figure(s.measurement_minus_map_std_nT)},
          {"drms_filter_m", json_figure(s.drms_filter_m)},
          {"drms_ins_m", json_figure(s.drms_ins_m)},
          {"drms_crlb_m", json_figure(s.drms_crlb_m)},
          {"nees_in_95_bounds", json_figure(s.nees_in_bounds)},
          {"nees_above_95_bound", json_figure(s.nees_above)},
          {"innovation_mean_nT", json_figure(s.innovation_mean_nT)},
          {"innovation_std_nT", json_figure(s.innovation_std_nT)},
          {"nis_mean", json_figure(s.nis_mean)},
          {"samples",
           {{"rows", s.rows},
            {"steps", c.steps},
            {"scored", s.scored},
            {"measurements_used", s.updates},
            {"map_compared", s.map_compared}}},
          {"faults",
           {{"ins_refused", c.invalid_ins},
            {"truth_refused", s.invalid_truth},
            {"ins_gaps", c.gaps},
            {"ins_jumps", c.ins_jumps},
            {"out_of_order_or_duplicate", c.out_of_order},
            {"off_map", c.off_map},
            {"nan_measurements", c.nan_measurements},
            {"measurements_refused", c.invalid_measurements},
            {"gated", c.gated},
            {"missing_measurements", c.missing_measurements},
            {"filter_restarts", c.filter_restarts}}}};
}

// The measured anomaly: a field as it is, or the model's (flight_navigation.h).
Eigen::VectorXd anomaly_of(const FlightData& f, const std::string& model_path,
                           const std::string& field, bool uncompensated = false) {
  if (!field.empty()) {
    if (!f.has(field)) throw Error(f.source() + ": field " + field + " (--anomaly) not found");
    return f.column(field);
  }
  return nav::measured_anomaly_nT(f, load_model_yaml(model_path), uncompensated);
}

// Why no measurement was used, in one line: where the track lies against the map.
std::string no_measurement_reason(const Navigated& n, const nav::FlightSamples& samples,
                                  const nav::AnomalyMap& map, const std::string& map_path) {
  const nav::NavigatorCounts& c = n.run.counts;
  double lat_lo = INFINITY, lat_hi = -INFINITY, lon_lo = INFINITY, lon_hi = -INFINITY;
  for (const nav::InsSample& s : samples.ins) {
    if (!nav::invalid_ins_reason(s).empty()) continue;
    lat_lo = std::min(lat_lo, s.lat_rad), lat_hi = std::max(lat_hi, s.lat_rad);
    lon_lo = std::min(lon_lo, s.lon_rad), lon_hi = std::max(lon_hi, s.lon_rad);
  }
  char buf[512];
  std::snprintf(buf, sizeof buf,
                "navigate: no measurement of %s was used in %ld steps (%ld off the map, %ld NaN, "
                "%ld refused, %ld gated, %ld INS samples refused): the INS track spans lat "
                "%.4f..%.4f, lon %.4f..%.4f deg; the map %s lat %.4f..%.4f, lon %.4f..%.4f deg",
                n.name.c_str(), c.steps, c.off_map, c.nan_measurements, c.invalid_measurements,
                c.gated, c.invalid_ins, lat_lo * kRadToDeg, lat_hi * kRadToDeg, lon_lo * kRadToDeg,
                lon_hi * kRadToDeg, map_path.c_str(), map.lat_rad[0] * kRadToDeg,
                map.lat_rad[map.lat_rad.size() - 1] * kRadToDeg, map.lon_rad[0] * kRadToDeg,
                map.lon_rad[map.lon_rad.size() - 1] * kRadToDeg);
  return buf;
}

// The rows of `lines` ("1001.10,1001.11"; empty: every row).
FlightData select_lines(FlightData f, const std::string& lines) {
  if (lines.empty()) return f;
  std::vector<double> wanted;
  for (const std::string& l : split_commas(lines)) {
    char* end = nullptr;
    const double v = std::strtod(l.c_str(), &end);
    if (!end || *end != '\0' || !std::isfinite(v))
      throw Error("--lines: '" + l + "' is not a line number");
    wanted.push_back(v);
  }
  if (!f.has("line")) throw Error(f.source() + ": field 'line' not found (--lines)");
  const std::vector<Eigen::Index> rows = f.select(wanted, {});
  if (rows.empty())
    throw Error("--lines " + lines + ": no sample of " + f.source() + " lies on them");
  return f.subset(rows);
}

// What online calibration learned, as JSON: each coefficient's prior and learned value and
// sigma, and the share of its prior variance the flight removed.
nlohmann::json learned_json(const std::vector<nav::LearnedCoefficient>& cs,
                            const std::string& prior) {
  nlohmann::json j;
  j["prior"] = prior;
  j["coefficients"] = nlohmann::json::array();
  long learned = 0, kept = 0;
  for (const auto& c : cs) {
    j["coefficients"].push_back({{"name", c.name},
                                 {"prior", c.prior},
                                 {"learned", c.learned},
                                 {"prior_sigma", c.prior_sigma},
                                 {"sigma", c.sigma},
                                 {"variance_removed", c.variance_removed}});
    learned += c.variance_removed > 0.5;
    kept += c.variance_removed < 0.1;
  }
  j["learned"] = learned;
  j["kept_at_prior"] = kept;
  return j;
}

// The learned coefficients, as a table.
void print_learned(const nlohmann::json& j) {
  const auto& cs = j["coefficients"];
  std::printf(
      "\nonline calibration (prior: %s): %ld of %zu coefficients learned (more than half "
      "of their prior variance removed), %ld kept at their prior (less than 10 %%: not "
      "observable on this flight's attitudes and map)\n",
      j["prior"].get<std::string>().c_str(), j["learned"].get<long>(), cs.size(),
      j["kept_at_prior"].get<long>());
  std::printf("  %-24s %12s %12s %10s %10s %9s\n", "coefficient", "prior", "learned", "sigma0",
              "sigma", "learned");
  for (const auto& c : cs)
    std::printf("  %-24s %12.4g %12.4g %10.3g %10.3g %8.0f%%\n",
                c["name"].get<std::string>().c_str(), c["prior"].get<double>(),
                c["learned"].get<double>(), c["prior_sigma"].get<double>(),
                c["sigma"].get<double>(), 100 * c["variance_removed"].get<double>());
}

// The filter's DRMS and its bound's over the steps from data time t_s on, m (NaN: none).
std::pair<double, double> drms_after(const nav::FlightRun& run, const nav::FlightRun& bound,
                                     const nav::FlightSamples& samples, double t_s) {
  double ss = 0, sb = 0;
  long n = 0, nb = 0;
  for (size_t k = 0; k < run.steps.size(); ++k) {
    const nav::NavigatorOutput& o = run.steps[k];
    const nav::InsSample& t = samples.truth[static_cast<size_t>(run.rows[k])];
    if (!(o.t_s >= t_s) || !nav::invalid_ins_reason(t).empty()) continue;
    ss += std::pow(nav::dlat_to_north_m(o.lat_rad - t.lat_rad, t.lat_rad), 2) +
          std::pow(nav::dlon_to_east_m(o.lon_rad - t.lon_rad, t.lat_rad), 2);
    ++n;
  }
  for (const nav::NavigatorOutput& o : bound.steps)
    if (o.t_s >= t_s) sb += o.position_cov_ned_m2(0, 0) + o.position_cov_ned_m2(1, 1), ++nb;
  return {n ? std::sqrt(ss / static_cast<double>(n)) : NAN,
          nb ? std::sqrt(sb / static_cast<double>(nb)) : NAN};
}

// What `magcomp navigate` is asked, as given on the command line.
struct NavigateArgs {
  std::string data, map_path, model_path, baseline, anomaly_field, json_path, report;
  double meas_sigma = 3.0, fogm_sigma = 3.0, fogm_tau = 600.0, init_pos_sigma = 3.0;
  std::string map_offset = "first", map_interp = "linear", map_representation = "on";
  bool model_variance = false;
  double map_sigma = NAN;
  bool online = false, cold = false;
  std::string prior_path, out_model, lines;
  double coef_walk = 0.0;
  int particles = 20000;
  double handover = 30.0;
};

// Refuses settings out of range and options that do not go together, naming the option.
void check_args(const NavigateArgs& a) {
  if (a.model_path.empty() == a.anomaly_field.empty())
    throw Error("navigate: give exactly one of --model and --anomaly");
  nav::require_setting(a.meas_sigma, 0, nav::kMaxSigma_nT, "--meas-sigma", "nT");
  nav::require_setting(a.fogm_sigma, 0, nav::kMaxSigma_nT, "--fogm-sigma", "nT");
  nav::require_setting(a.fogm_tau, 0, nav::kMaxTimeConstant_s, "--fogm-tau", "s");
  nav::require_setting(a.init_pos_sigma, 0, nav::kMaxPositionSigma_m, "--init-pos-sigma", "m");
  if (!std::isnan(a.map_sigma))
    nav::require_setting(a.map_sigma, 0, nav::kMaxSigma_nT, "--map-sigma", "nT", true);
  if (a.model_variance && a.model_path.empty())
    throw Error("navigate: --model-variance needs --model");
  if (!a.online && (a.cold || !a.prior_path.empty() || !a.out_model.empty()))
    throw Error("navigate: --cold, --prior and --out-model go with --online");
  if (a.online && a.model_path.empty())
    throw Error("navigate: --online needs --model (the terms to learn)");
  if (a.cold && !a.prior_path.empty()) throw Error("navigate: give --prior or --cold, not both");
  nav::require_setting(a.coef_walk, 0, 10, "--coefficient-walk", "(share per sqrt(h))", true);
  if (a.particles != 0 && (a.particles < 10 || a.particles > 1000000))
    throw Error("--particles: must be 0 (none) or in 10..1000000");
  nav::require_setting(a.handover, 0, nav::kMaxPositionSigma_m, "--handover-sigma", "m");
}

// What every navigated series shares: the flight, its samples, the map at the flight's height,
// the filter's settings, the particle filter's for a far start, and the Cramér-Rao bound.
struct NavigationSetup {
  FlightData flight;
  nav::FlightSamples samples;
  nav::AnomalyMap map;
  double map_sigma_nT = NAN;
  nav::FilterSettings settings;
  std::optional<nav::ParticleSettings> cold_start;
  nav::FlightRun bound;
};

NavigationSetup setup_navigation(const NavigateArgs& a) {
  NavigationSetup s{select_lines(read_flight(a.data), a.lines), {}, {}, NAN, {}, {}, {}};
  s.samples = nav::flight_samples(s.flight);
  s.map = nav::read_anomaly_map(a.map_path);
  if (a.map_interp == "cubic") s.map.interpolation = nav::AnomalyMap::Interpolation::Cubic;
  const double mean_alt_m = s.samples.mean_alt_m;
  if (std::isfinite(mean_alt_m) && mean_alt_m > s.map.alt_m + 1.0)
    s.map = nav::continued_to(s.map, mean_alt_m);
  if (std::isfinite(mean_alt_m) && mean_alt_m < s.map.alt_m - 1.0)
    std::fprintf(stderr,
                 "warning: %s: the map lies %.0f m above the flight's mean height (%.0f m above "
                 "the ellipsoid): used as it is (no downward continuation)\n",
                 a.map_path.c_str(), s.map.alt_m - mean_alt_m, mean_alt_m);
  s.map_sigma_nT = std::isnan(a.map_sigma) ? s.map.error_sigma_nT : a.map_sigma;
  nav::ModelSigmas sig;
  sig.meas_var_nT2 = a.meas_sigma * a.meas_sigma;
  sig.fogm_nT = a.fogm_sigma;
  sig.map_representation_var = a.map_representation == "on";
  sig.taus.fogm_s = a.fogm_tau;
  sig.init_pos_m = a.init_pos_sigma;
  double lat1 = NAN;  // the first valid INS latitude: the filter's initial covariance is there
  for (const nav::InsSample& ins : s.samples.ins)
    if (nav::invalid_ins_reason(ins).empty()) {
      lat1 = ins.lat_rad;
      break;
    }
  if (!std::isfinite(lat1))
    throw Error(a.data +
                ": no INS sample is usable (every one has a position or attitude that "
                "is not finite, or lies at a pole or outside [-12, 100] km)");
  s.settings = nav::filter_model(s.samples.dt_s, lat1, sig);
  s.settings.offset_from_first = a.map_offset == "first";
  if (a.init_pos_sigma > 100.0 && a.particles > 0) {  // a start far from the truth: particles first
    nav::ParticleSettings ps;
    ps.particles = a.particles;
    ps.init_sigma_m = a.init_pos_sigma;
    ps.handover_sigma_m = a.handover;
    s.cold_start = ps;
  }
  s.bound = nav::crlb_run(s.samples.truth, s.map, s.settings, s.samples.dt_s);
  return s;
}

// R per sample from the model at `path` with --model-variance: its variance plus the map's
// (nT^2); none without.
std::optional<Eigen::VectorXd> variance_of(const NavigateArgs& a, const NavigationSetup& s,
                                           const std::string& path) {
  if (!a.model_variance) return std::nullopt;
  const Eigen::VectorXd v = compensation_variance_nT2(load_model_yaml(path), s.flight);
  return Eigen::VectorXd(v.array() + s.map_sigma_nT * s.map_sigma_nT);
}

// Navigates the measurement z_nT (R r_nT2, else the settings'), scored against the truth. Online:
// the model's columns ride with it under `online_settings`, and the measurement compared with
// the map is z compensated as the filter had learned it at each step.
Navigated navigate_series(const NavigateArgs& a, const NavigationSetup& s, const std::string& key,
                          const std::string& name, const Eigen::VectorXd& z_nT,
                          const std::optional<Eigen::VectorXd>& r_nT2,
                          const nav::OnlineMeasurement* online_in = nullptr,
                          const nav::FilterSettings* online_settings = nullptr) {
  Navigated n;
  n.key = key;
  n.name = name;
  n.run = nav::run_flight(s.samples.ins, z_nT, r_nT2 ? &*r_nT2 : nullptr, s.map,
                          online_settings ? *online_settings : s.settings, s.samples.dt_s,
                          online_in ? &online_in->columns : nullptr,
                          s.cold_start ? &*s.cold_start : nullptr);
  Eigen::VectorXd compared = z_nT;
  if (online_in) {
    compared.setConstant(NAN);
    for (size_t k = 0; k < n.run.steps.size(); ++k) {
      const Eigen::Index row = n.run.rows[k];
      compared[row] = z_nT[row] - online_in->columns.row(row).dot(n.run.steps[k].coefficients);
    }
  }
  n.scores = nav::score_run(n.run, s.bound, s.samples, compared, s.map);
  if (n.scores.updates == 0) throw Error(no_measurement_reason(n, s.samples, s.map, a.map_path));
  if (n.scores.scored == 0)
    throw Error(a.data +
                ": no true position is usable to score the navigation (lat, lon, "
                "alt and the attitude not finite, at a pole or out of range in " +
                std::to_string(n.scores.invalid_truth) + " of " + std::to_string(n.scores.rows) +
                " rows)");
  return n;
}

// --online: the model's coefficients learned in the filter (then, with --out-model, re-fitted
// over the flight at the filter's positions and written), and the model as given beside it.
// Appends the series to `rows`; returns what was learned as JSON; *anomaly_nT: the raw anomaly.
nlohmann::json navigate_online(const NavigateArgs& a, const NavigationSetup& s,
                               const OutputGuard& guard, std::vector<Navigated>* rows,
                               Eigen::VectorXd* anomaly_nT) {
  const Model model = load_model_yaml(a.model_path);
  const Model prior = a.prior_path.empty() ? model : load_model_yaml(a.prior_path);
  const std::string prior_name = a.prior_path.empty() ? a.model_path : a.prior_path;
  nav::CoefficientPriorSettings ps;
  ps.cold = a.cold;
  ps.walk_share_per_sqrt_h = a.coef_walk;
  nav::FilterSettings online_settings = s.settings;
  nav::set_coefficient_prior(model, &prior, ps, &online_settings);
  const nav::OnlineMeasurement om = nav::online_measurement(s.flight, model);
  *anomaly_nT = om.raw_anomaly_nT;
  rows->push_back(navigate_series(a, s, "",
                                  a.cold ? "online (cold)" : "online (prior " + prior_name + ")",
                                  om.raw_anomaly_nT, std::nullopt, &om, &online_settings));
  const Navigated& n = rows->back();
  const Eigen::VectorXd learned = n.run.steps.back().coefficients;
  nlohmann::json j = learned_json(
      nav::learned_coefficients(model, online_settings, learned, n.run.coefficient_covariance),
      a.cold ? "cold" : prior_name);
  if (!a.out_model.empty()) {
    // Once flown: the whole flight re-fitted against the map at the filter's positions.
    Eigen::VectorXd lat(static_cast<Eigen::Index>(n.run.steps.size())), lon(lat.size());
    for (size_t k = 0; k < n.run.steps.size(); ++k) {
      lat[static_cast<Eigen::Index>(k)] = n.run.steps[k].lat_rad;
      lon[static_cast<Eigen::Index>(k)] = n.run.steps[k].lon_rad;
    }
    const nav::SmoothedCoefficients sm = nav::smoothed_coefficients(
        om, n.run.rows, lat, lon, s.map, learned, n.run.coefficient_covariance);
    Model out = nav::learned_model(model, sm.coefficients, sm.covariance);
    out.report.estimates.push_back("coefficients learned online in the navigation filter on " +
                                   a.data + " against the map " + a.map_path +
                                   ", then re-fitted over the " + std::to_string(sm.rows) +
                                   " samples on the map at the filter's positions");
    j["smoothed"] = {{"rows", sm.rows}, {"residual_std_nT", json_figure(sm.residual_std_nT)}};
    save_model_yaml(out, a.out_model, guard.input_paths());
  }
  if (model.fitted())
    rows->push_back(navigate_series(a, s, "static", a.model_path + " (as given)",
                                    anomaly_of(s.flight, a.model_path, ""),
                                    variance_of(a, s, a.model_path)));
  return j;
}

// The particle filter's hand-over (a far start), in one line.
void print_cold_start(const NavigationSetup& s, const Navigated& first) {
  const nav::ParticleSettings& cs = *s.cold_start;
  if (std::isfinite(first.run.handover_t_s)) {
    const double t0 = s.samples.ins.empty() ? 0.0 : s.samples.ins.front().t_s;
    const auto [after_m, bound_m] =
        drms_after(first.run, s.bound, s.samples, first.run.handover_t_s);
    std::printf(
        "cold start: %d particles from %.0f m; handed over to the EKF after %.1f s; "
        "from then on DRMS %.1f m (CRLB %.1f m)\n",
        cs.particles, cs.init_sigma_m, first.run.handover_t_s - t0, after_m, bound_m);
  } else
    std::printf(
        "warning: cold start: %d particles from %.0f m never gathered below %.0f m: the "
        "particle filter navigated the whole flight\n",
        cs.particles, cs.init_sigma_m, cs.handover_sigma_m);
}

// The table of the series, then what the figures come from and every fault met on the way.
void print_navigation(const NavigateArgs& a, const NavigationSetup& s,
                      const std::vector<Navigated>& rows) {
  std::printf("%s: %ld samples at %.3g s, map %ldx%ld cells at %.0f m\n", a.data.c_str(),
              static_cast<long>(s.flight.size()), s.samples.dt_s,
              static_cast<long>(s.map.map_nT.rows()), static_cast<long>(s.map.map_nT.cols()),
              s.map.alt_m);
  std::printf("%-32s %12s %11s %9s %10s %12s %16s %10s\n", "measurement", "meas-map nT", "filter m",
              "INS m", "CRLB m", "NEES in 95%", "innovation nT", "used");
  for (const Navigated& n : rows) {
    const nav::NavigationScores& sc = n.scores;
    const std::string innov =
        figure(sc.innovation_mean_nT, "%.2f") + " +- " + figure(sc.innovation_std_nT, "%.2f");
    std::printf("%-32s %12s %11s %9s %10s %12s %16s %10ld\n", n.name.c_str(),
                figure(sc.measurement_minus_map_std_nT, "%.3f").c_str(),
                figure(sc.drms_filter_m, "%.1f").c_str(), figure(sc.drms_ins_m, "%.1f").c_str(),
                figure(sc.drms_crlb_m, "%.1f").c_str(),
                figure(100 * sc.nees_in_bounds, "%.0f%%").c_str(), innov.c_str(), sc.updates);
  }
  const nav::NavigationScores& s0 = rows.front().scores;
  const nav::NavigatorCounts& c = s0.counts;
  std::printf(
      "samples: %ld rows, %ld filter steps, %ld scored against the truth, %ld "
      "measurements used\n",
      s0.rows, c.steps, s0.scored, s0.updates);
  const long faults = c.invalid_ins + s0.invalid_truth + c.gaps + c.ins_jumps + c.out_of_order +
                      c.off_map + c.nan_measurements + c.invalid_measurements + c.gated +
                      c.missing_measurements + c.filter_restarts;
  if (faults > 0)
    std::printf(
        "warning: inputs the filter could not use: %ld INS samples refused, %ld true "
        "positions refused, %ld INS gaps, %ld INS jumps, %ld duplicate or out-of-order stamps, "
        "%ld "
        "measurements off the map, %ld NaN, %ld refused (beyond 1e6 nT), %ld gated, %ld "
        "missing, %ld filter restarts\n",
        c.invalid_ins, s0.invalid_truth, c.gaps, c.ins_jumps, c.out_of_order, c.off_map,
        c.nan_measurements, c.invalid_measurements, c.gated, c.missing_measurements,
        c.filter_restarts);
}

// The figures as JSON: the first series at the top, the others under their keys.
nlohmann::json navigation_json(const NavigateArgs& a, const NavigationSetup& s,
                               const std::vector<Navigated>& rows) {
  const Navigated& first = rows.front();
  nlohmann::json j = to_json(first.scores);
  j["data"] = a.data;
  j["map"] = a.map_path;
  j["measurement"] = first.name;
  if (s.cold_start) {
    const double t0 = s.samples.ins.empty() ? 0.0 : s.samples.ins.front().t_s;
    const auto [after_m, bound_m] =
        drms_after(first.run, s.bound, s.samples, first.run.handover_t_s);
    j["cold_start"] = {{"particles", s.cold_start->particles},
                       {"init_sigma_m", s.cold_start->init_sigma_m},
                       {"handover_after_s", json_figure(first.run.handover_t_s - t0)},
                       {"drms_after_handover_m", json_figure(after_m)},
                       {"crlb_after_handover_m", json_figure(bound_m)}};
  }
  for (size_t k = 1; k < rows.size(); ++k) {
    nlohmann::json& r = j[rows[k].key];
    r = to_json(rows[k].scores);
    if (rows[k].key == "baseline") r["model"] = a.baseline;
  }
  return j;
}

void run_navigate(const NavigateArgs& a) {
  check_args(a);
  OutputGuard guard({{"--data", a.data},
                     {"--map", a.map_path},
                     {"--model", a.model_path},
                     {"--baseline", a.baseline},
                     {"--prior", a.prior_path}});
  guard.add_output("--json", a.json_path);
  guard.add_output("--out-model", a.out_model);
  guard.add_output_dir("--report", a.report,
                       {"tracks.h5", "navigation.json", "index.html", "tracks.png", "errors.png",
                        "innovations.png"});
  const NavigationSetup s = setup_navigation(a);
  std::vector<Navigated> rows;
  Eigen::VectorXd main_anomaly;
  nlohmann::json online_json;
  if (a.online) {
    online_json = navigate_online(a, s, guard, &rows, &main_anomaly);
  } else {
    main_anomaly = anomaly_of(s.flight, a.model_path, a.anomaly_field);
    rows.push_back(navigate_series(
        a, s, "", a.anomaly_field.empty() ? a.model_path : a.anomaly_field, main_anomaly,
        a.model_path.empty() ? std::nullopt : variance_of(a, s, a.model_path)));
  }
  if (!a.baseline.empty())
    rows.push_back(navigate_series(a, s, "baseline", a.baseline,
                                   anomaly_of(s.flight, a.baseline, ""),
                                   variance_of(a, s, a.baseline)));
  if (!a.model_path.empty())
    rows.push_back(navigate_series(a, s, "uncompensated", "uncompensated",
                                   anomaly_of(s.flight, a.model_path, "", true), std::nullopt));
  guard.check_inputs_unchanged();

  if (s.cold_start) print_cold_start(s, rows.front());
  print_navigation(a, s, rows);
  nlohmann::json j = navigation_json(a, s, rows);
  if (a.online) {
    j["online"] = online_json;
    print_learned(online_json);
  }
  if (!a.json_path.empty()) write_file_atomic(a.json_path, j.dump(2) + "\n", guard.input_paths());
  if (!a.report.empty())
    write_navigation_report(a.report, s.samples, rows.front(), main_anomaly, s.map, j,
                            guard.input_paths());
}

// The filter's options: the noise model, the map's use, the start.
void add_filter_options(CLI::App* cmd, NavigateArgs* a) {
  cmd->add_option("--meas-sigma", a->meas_sigma, "measurement noise std, nT (default 3)");
  cmd->add_option("--fogm-sigma", a->fogm_sigma, "FOGM catch-all std, nT (default 3)");
  cmd->add_option("--fogm-tau", a->fogm_tau, "FOGM catch-all time constant, s (default 600)");
  cmd->add_option("--init-pos-sigma", a->init_pos_sigma, "initial position std, m (default 3)");
  cmd->add_flag("--model-variance", a->model_variance,
                "R per sample: the model's variance (its coefficients' uncertainty and its "
                "held-out error, as the compensator publishes it) plus --map-sigma squared, "
                "instead of --meas-sigma squared");
  cmd->add_option("--map-sigma", a->map_sigma,
                  "the map's error std, nT, with --model-variance (default: the map file's "
                  "error_sigma_nT, else 0.3)");
  cmd->add_option("--map-interp", a->map_interp,
                  "the map's interpolation: linear (bilinear, MagNav.jl's test vectors') or cubic "
                  "(cubic convolution); default linear")
      ->check(CLI::IsMember({"linear", "cubic"}));
  cmd->add_option("--map-representation", a->map_representation,
                  "'on': each measurement's R also holds the map's interpolation error and the "
                  "linearisation of the map over the position's covariance (from the map's "
                  "curvature); 'off': R as given, MagNav.jl's filter (default on)")
      ->check(CLI::IsMember({"on", "off"}));
  cmd->add_option("--map-offset", a->map_offset,
                  "'first': remove the first measurement minus the map (at the INS position) from "
                  "all measurements, the compensation's constant offset; 'none': MagNav.jl's "
                  "filter (default first)")
      ->check(CLI::IsMember({"first", "none"}));
  cmd->add_option("--particles", a->particles,
                  "a start far from the truth (--init-pos-sigma above 100 m): a particle filter "
                  "of this many particles runs first and hands over to the EKF once its cloud "
                  "has gathered (default 20000; 0: the EKF alone)");
  cmd->add_option("--handover-sigma", a->handover,
                  "the cloud's horizontal 1-sigma, m, below which the particle filter hands over "
                  "(default 30)");
}

// Online calibration's options.
void add_online_options(CLI::App* cmd, NavigateArgs* a) {
  cmd->add_flag("--online", a->online,
                "learn the model's coefficients in the filter (online calibration): they ride "
                "as random-walk states, the map their reference; the measurement is the raw "
                "scalar less the IGRF and the diurnal");
  cmd->add_option("--prior", a->prior_path,
                  "with --online: the fitted model whose coefficients (and their covariance) "
                  "start the states (default --model)");
  cmd->add_flag("--cold", a->cold,
                "with --online: start the coefficients at zero (permanent 200 nT, induced and "
                "eddy 500 nT, other terms 50 per unit, 1-sigma)");
  cmd->add_option("--coefficient-walk", a->coef_walk,
                  "with --online: the coefficients' random walk, a share of their prior sigma "
                  "per sqrt(hour) (default 0: constant within a flight)");
  cmd->add_option("--out-model", a->out_model,
                  "with --online: write the learned model (the coefficients at the end and their "
                  "covariance) here, for evaluate and the compensator");
}

}  // namespace

void add_navigate(CLI::App& app) {
  auto* cmd = app.add_subcommand(
      "navigate", "navigate on the compensated anomaly with a map (EKF); DRMS in metres");
  auto a = std::make_shared<NavigateArgs>();
  cmd->add_option("--data", a->data,
                  "flight HDF5: truth lat, lon (deg), alt/msl (m), roll/pitch/yaw; INS ins_lat, "
                  "ins_lon (rad or deg), ins_alt, ins_roll/pitch/yaw (deg)")
      ->required();
  cmd->add_option("--map", a->map_path, "anomaly map HDF5 (MagNav.jl's names: map, xx, yy, alt)")
      ->required();
  cmd->add_option("--model", a->model_path,
                  "fitted model YAML: its compensation less IGRF/diurnal");
  cmd->add_option("--baseline", a->baseline, "another fitted model, scored the same way");
  cmd->add_option("--anomaly", a->anomaly_field,
                  "a field of --data already holding the anomaly (nT), instead of --model");
  cmd->add_option("--json", a->json_path, "write the figures as JSON here");
  cmd->add_option("--report", a->report,
                  "write the tracks (truth, INS, filter with its 2-sigma ellipse) on the map, the "
                  "errors and innovations as an HTML page into this directory");
  cmd->add_option("--lines", a->lines,
                  "navigate on these lines only, comma-separated (e.g. the survey lines, not the "
                  "calibration box); the gaps between them are propagated across");
  add_filter_options(cmd, a.get());
  add_online_options(cmd, a.get());
  cmd->callback([a] { run_navigate(*a); });
}

}  // namespace magcomp::cli
