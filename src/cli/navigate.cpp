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
#include "subcommands.h"

namespace magcomp::cli {
namespace {

// One measurement series navigated: the run, its scores, its name.
struct Navigated {
  std::string
      key;  // its JSON key: "" (the figures at the top), "baseline", "static", "uncompensated"
  std::string name;
  nav::FlightRun run;
  nav::NavigationScores scores;
};

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

H5Array array_of(const Eigen::VectorXd& v) {
  H5Array a;
  a.dims = {static_cast<size_t>(v.size())};
  a.values.assign(v.data(), v.data() + v.size());
  return a;
}

// DIR/tracks.h5 (truth, INS and filter tracks in degrees at each step, errors and the filter's
// horizontal covariance in metres, innovations; the map), DIR/navigation.json, then the page.
void write_report(const std::string& dir, const nav::FlightSamples& samples, const Navigated& n,
                  const Eigen::VectorXd& anomaly_nT, const nav::AnomalyMap& map,
                  const nlohmann::json& j, const std::vector<std::string>& inputs) {
  make_report_dir(dir);
  const auto m = static_cast<Eigen::Index>(n.run.steps.size());
  Eigen::VectorXd t(m), tlat(m), tlon(m), ilat(m), ilon(m), flat(m), flon(m), en(m), ee(m), ien(m),
      iee(m), pnn(m), pee(m), pne(m), z(m), v(m), vv(m);
  const double t0 = m > 0 ? n.run.steps[0].t_s : 0.0;
  for (Eigen::Index i = 0; i < m; ++i) {
    const nav::NavigatorOutput& o = n.run.steps[static_cast<size_t>(i)];
    const nav::InsSample& tr =
        samples.truth[static_cast<size_t>(n.run.rows[static_cast<size_t>(i)])];
    const bool truth_ok = nav::invalid_ins_reason(tr).empty();
    t[i] = o.t_s - t0;
    tlat[i] = truth_ok ? tr.lat_rad * kRadToDeg : NAN;
    tlon[i] = truth_ok ? tr.lon_rad * kRadToDeg : NAN;
    ilat[i] = o.ins_lat_rad * kRadToDeg;
    ilon[i] = o.ins_lon_rad * kRadToDeg;
    flat[i] = o.lat_rad * kRadToDeg;
    flon[i] = o.lon_rad * kRadToDeg;
    en[i] = truth_ok ? nav::dlat_to_north_m(o.lat_rad - tr.lat_rad, tr.lat_rad) : NAN;
    ee[i] = truth_ok ? nav::dlon_to_east_m(o.lon_rad - tr.lon_rad, tr.lat_rad) : NAN;
    ien[i] = truth_ok ? nav::dlat_to_north_m(o.ins_lat_rad - tr.lat_rad, tr.lat_rad) : NAN;
    iee[i] = truth_ok ? nav::dlon_to_east_m(o.ins_lon_rad - tr.lon_rad, tr.lat_rad) : NAN;
    pnn[i] = o.position_cov_ned_m2(0, 0);
    pee[i] = o.position_cov_ned_m2(1, 1);
    pne[i] = o.position_cov_ned_m2(0, 1);
    z[i] = anomaly_nT[n.run.rows[static_cast<size_t>(i)]];
    v[i] = o.step.updated ? o.step.innovation_nT : NAN;
    vv[i] = o.step.innovation_var_nT2;
  }
  H5Array grid;
  grid.dims = {static_cast<size_t>(map.map_nT.rows()), static_cast<size_t>(map.map_nT.cols())};
  for (Eigen::Index r = 0; r < map.map_nT.rows(); ++r)
    for (Eigen::Index c = 0; c < map.map_nT.cols(); ++c)
      grid.values.push_back(map.mask.size() == 0 || map.mask(r, c) != 0 ? map.map_nT(r, c) : NAN);
  write_h5_arrays(dir + "/tracks.h5",
                  {{"t_s", array_of(t)},
                   {"true_lat_deg", array_of(tlat)},
                   {"true_lon_deg", array_of(tlon)},
                   {"ins_lat_deg", array_of(ilat)},
                   {"ins_lon_deg", array_of(ilon)},
                   {"filter_lat_deg", array_of(flat)},
                   {"filter_lon_deg", array_of(flon)},
                   {"error_north_m", array_of(en)},
                   {"error_east_m", array_of(ee)},
                   {"ins_error_north_m", array_of(ien)},
                   {"ins_error_east_m", array_of(iee)},
                   {"cov_north_m2", array_of(pnn)},
                   {"cov_east_m2", array_of(pee)},
                   {"cov_north_east_m2", array_of(pne)},
                   {"measurement_nT", array_of(z)},
                   {"innovation_nT", array_of(v)},
                   {"innovation_var_nT2", array_of(vv)},
                   {"map_lat_deg", array_of(map.lat_rad * kRadToDeg)},
                   {"map_lon_deg", array_of(map.lon_rad * kRadToDeg)},
                   {"map_nT", grid}},
                  inputs);
  write_file_atomic(dir + "/navigation.json", j.dump(2) + "\n", inputs);
  run_report_page("magcomp_nav_report.py", dir, "tracks.h5 and navigation.json");
}

}  // namespace

void add_navigate(CLI::App& app) {
  auto* cmd = app.add_subcommand(
      "navigate", "navigate on the compensated anomaly with a map (EKF); DRMS in metres");
  auto data = std::make_shared<std::string>();
  auto map_path = std::make_shared<std::string>();
  auto model_path = std::make_shared<std::string>();
  auto baseline = std::make_shared<std::string>();
  auto anomaly_field = std::make_shared<std::string>();
  auto json_path = std::make_shared<std::string>();
  auto report = std::make_shared<std::string>();
  auto meas_sigma = std::make_shared<double>(3.0);
  auto fogm_sigma = std::make_shared<double>(3.0);
  auto fogm_tau = std::make_shared<double>(600.0);
  auto init_pos_sigma = std::make_shared<double>(3.0);
  auto map_offset = std::make_shared<std::string>("first");
  auto map_interp = std::make_shared<std::string>("linear");
  auto map_representation = std::make_shared<std::string>("on");
  auto model_variance = std::make_shared<bool>(false);
  auto map_sigma = std::make_shared<double>(NAN);
  auto online = std::make_shared<bool>(false);
  auto cold = std::make_shared<bool>(false);
  auto prior_path = std::make_shared<std::string>();
  auto out_model = std::make_shared<std::string>();
  auto lines = std::make_shared<std::string>();
  auto coef_walk = std::make_shared<double>(0.0);
  auto particles = std::make_shared<int>(20000);
  auto handover = std::make_shared<double>(30.0);
  cmd->add_option("--data", *data,
                  "flight HDF5: truth lat, lon (deg), alt/msl (m), roll/pitch/yaw; INS ins_lat, "
                  "ins_lon (rad or deg), ins_alt, ins_roll/pitch/yaw (deg)")
      ->required();
  cmd->add_option("--map", *map_path, "anomaly map HDF5 (MagNav.jl's names: map, xx, yy, alt)")
      ->required();
  cmd->add_option("--model", *model_path, "fitted model YAML: its compensation less IGRF/diurnal");
  cmd->add_option("--baseline", *baseline, "another fitted model, scored the same way");
  cmd->add_option("--anomaly", *anomaly_field,
                  "a field of --data already holding the anomaly (nT), instead of --model");
  cmd->add_option("--json", *json_path, "write the figures as JSON here");
  cmd->add_option("--report", *report,
                  "write the tracks (truth, INS, filter with its 2-sigma ellipse) on the map, the "
                  "errors and innovations as an HTML page into this directory");
  cmd->add_option("--meas-sigma", *meas_sigma, "measurement noise std, nT (default 3)");
  cmd->add_option("--fogm-sigma", *fogm_sigma, "FOGM catch-all std, nT (default 3)");
  cmd->add_option("--fogm-tau", *fogm_tau, "FOGM catch-all time constant, s (default 600)");
  cmd->add_option("--init-pos-sigma", *init_pos_sigma, "initial position std, m (default 3)");
  cmd->add_flag("--model-variance", *model_variance,
                "R per sample: the model's variance (its coefficients' uncertainty and its "
                "held-out error, as the compensator publishes it) plus --map-sigma squared, "
                "instead of --meas-sigma squared");
  cmd->add_option("--map-sigma", *map_sigma,
                  "the map's error std, nT, with --model-variance (default: the map file's "
                  "error_sigma_nT, else 0.3)");
  cmd->add_option("--map-interp", *map_interp,
                  "the map's interpolation: linear (bilinear, MagNav.jl's test vectors') or cubic "
                  "(cubic convolution); default linear")
      ->check(CLI::IsMember({"linear", "cubic"}));
  cmd->add_option("--map-representation", *map_representation,
                  "'on': each measurement's R also holds the map's interpolation error and the "
                  "linearisation of the map over the position's covariance (from the map's "
                  "curvature); 'off': R as given, MagNav.jl's filter (default on)")
      ->check(CLI::IsMember({"on", "off"}));
  cmd->add_option("--map-offset", *map_offset,
                  "'first': remove the first measurement minus the map (at the INS position) from "
                  "all measurements, the compensation's constant offset; 'none': MagNav.jl's "
                  "filter (default first)")
      ->check(CLI::IsMember({"first", "none"}));
  cmd->add_flag("--online", *online,
                "learn the model's coefficients in the filter (online calibration): they ride "
                "as random-walk states, the map their reference; the measurement is the raw "
                "scalar less the IGRF and the diurnal");
  cmd->add_option("--prior", *prior_path,
                  "with --online: the fitted model whose coefficients (and their covariance) "
                  "start the states (default --model)");
  cmd->add_flag("--cold", *cold,
                "with --online: start the coefficients at zero (permanent 200 nT, induced and "
                "eddy 500 nT, other terms 50 per unit, 1-sigma)");
  cmd->add_option("--coefficient-walk", *coef_walk,
                  "with --online: the coefficients' random walk, a share of their prior sigma "
                  "per sqrt(hour) (default 0: constant within a flight)");
  cmd->add_option("--out-model", *out_model,
                  "with --online: write the learned model (the coefficients at the end and their "
                  "covariance) here, for evaluate and the compensator");
  cmd->add_option("--particles", *particles,
                  "a start far from the truth (--init-pos-sigma above 100 m): a particle filter "
                  "of this many particles runs first and hands over to the EKF once its cloud "
                  "has gathered (default 20000; 0: the EKF alone)");
  cmd->add_option("--handover-sigma", *handover,
                  "the cloud's horizontal 1-sigma, m, below which the particle filter hands over "
                  "(default 30)");
  cmd->add_option("--lines", *lines,
                  "navigate on these lines only, comma-separated (e.g. the survey lines, not the "
                  "calibration box); the gaps between them are propagated across");
  cmd->callback([=] {
    if (model_path->empty() == anomaly_field->empty())
      throw Error("navigate: give exactly one of --model and --anomaly");
    nav::require_setting(*meas_sigma, 0, nav::kMaxSigma_nT, "--meas-sigma", "nT");
    nav::require_setting(*fogm_sigma, 0, nav::kMaxSigma_nT, "--fogm-sigma", "nT");
    nav::require_setting(*fogm_tau, 0, nav::kMaxTimeConstant_s, "--fogm-tau", "s");
    nav::require_setting(*init_pos_sigma, 0, nav::kMaxPositionSigma_m, "--init-pos-sigma", "m");
    if (!std::isnan(*map_sigma))
      nav::require_setting(*map_sigma, 0, nav::kMaxSigma_nT, "--map-sigma", "nT", true);
    if (*model_variance && model_path->empty())
      throw Error("navigate: --model-variance needs --model");
    if (!*online && (*cold || !prior_path->empty() || !out_model->empty()))
      throw Error("navigate: --cold, --prior and --out-model go with --online");
    if (*online && model_path->empty())
      throw Error("navigate: --online needs --model (the terms to learn)");
    if (*cold && !prior_path->empty()) throw Error("navigate: give --prior or --cold, not both");
    nav::require_setting(*coef_walk, 0, 10, "--coefficient-walk", "(share per sqrt(h))", true);
    if (*particles != 0 && (*particles < 10 || *particles > 1000000))
      throw Error("--particles: must be 0 (none) or in 10..1000000");
    nav::require_setting(*handover, 0, nav::kMaxPositionSigma_m, "--handover-sigma", "m");
    OutputGuard guard({{"--data", *data},
                       {"--map", *map_path},
                       {"--model", *model_path},
                       {"--baseline", *baseline},
                       {"--prior", *prior_path}});
    guard.add_output("--json", *json_path);
    guard.add_output("--out-model", *out_model);
    guard.add_output_dir("--report", *report,
                         {"tracks.h5", "navigation.json", "index.html", "tracks.png", "errors.png",
                          "innovations.png"});
    const FlightData f = select_lines(read_flight(*data), *lines);
    const nav::FlightSamples samples = nav::flight_samples(f);
    nav::AnomalyMap map = nav::read_anomaly_map(*map_path);
    if (*map_interp == "cubic") map.interpolation = nav::AnomalyMap::Interpolation::Cubic;
    if (std::isfinite(samples.mean_alt_m) && samples.mean_alt_m > map.alt_m + 1.0)
      map = nav::continued_to(map, samples.mean_alt_m);
    if (std::isfinite(samples.mean_alt_m) && samples.mean_alt_m < map.alt_m - 1.0)
      std::fprintf(stderr,
                   "warning: %s: the map lies %.0f m above the flight's mean height (%.0f m above "
                   "the ellipsoid): used as it is (no downward continuation)\n",
                   map_path->c_str(), map.alt_m - samples.mean_alt_m, samples.mean_alt_m);
    const double map_sigma_nT = std::isnan(*map_sigma) ? map.error_sigma_nT : *map_sigma;
    nav::ModelSigmas sig;
    sig.meas_var_nT2 = *meas_sigma * *meas_sigma;
    sig.fogm_nT = *fogm_sigma;
    sig.map_representation_var = *map_representation == "on";
    sig.taus.fogm_s = *fogm_tau;
    sig.init_pos_m = *init_pos_sigma;
    double lat1 = NAN;  // the first valid INS latitude: the filter's initial covariance is there
    for (const nav::InsSample& s : samples.ins)
      if (nav::invalid_ins_reason(s).empty()) {
        lat1 = s.lat_rad;
        break;
      }
    if (!std::isfinite(lat1))
      throw Error(*data +
                  ": no INS sample is usable (every one has a position or attitude that "
                  "is not finite, or lies at a pole or outside [-12, 100] km)");
    nav::FilterSettings settings = nav::filter_model(samples.dt_s, lat1, sig);
    settings.offset_from_first = *map_offset == "first";
    // A start far from the truth: the particle filter first.
    std::optional<nav::ParticleSettings> cold_start;
    if (*init_pos_sigma > 100.0 && *particles > 0) {
      nav::ParticleSettings ps;
      ps.particles = *particles;
      ps.init_sigma_m = *init_pos_sigma;
      ps.handover_sigma_m = *handover;
      cold_start = ps;
    }
    const nav::FlightRun bound = nav::crlb_run(samples.truth, map, settings, samples.dt_s);

    // R per sample from a model: its variance plus the map's.
    auto r_of = [&](const std::string& path) -> std::optional<Eigen::VectorXd> {
      if (!*model_variance) return std::nullopt;
      Eigen::VectorXd v = compensation_variance_nT2(load_model_yaml(path), f);
      return Eigen::VectorXd(v.array() + map_sigma_nT * map_sigma_nT);
    };
    std::vector<Navigated> rows;
    Eigen::VectorXd main_anomaly;
    auto navigate = [&](const std::string& key, const std::string& name, const Eigen::VectorXd& z,
                        const std::optional<Eigen::VectorXd>& r,
                        const nav::OnlineMeasurement* online_in = nullptr,
                        const nav::FilterSettings* online_settings = nullptr) {
      Navigated n;
      n.key = key;
      n.name = name;
      n.run = nav::run_flight(samples.ins, z, r ? &*r : nullptr, map,
                              online_settings ? *online_settings : settings, samples.dt_s,
                              online_in ? &online_in->columns : nullptr,
                              cold_start ? &*cold_start : nullptr);
      // Online, the measurement against the map is the raw one compensated as the filter had
      // learned it at each step.
      Eigen::VectorXd compared = z;
      if (online_in) {
        compared.setConstant(NAN);
        for (size_t k = 0; k < n.run.steps.size(); ++k) {
          const Eigen::Index row = n.run.rows[k];
          compared[row] = z[row] - online_in->columns.row(row).dot(n.run.steps[k].coefficients);
        }
      }
      n.scores = nav::score_run(n.run, bound, samples, compared, map);
      if (n.scores.updates == 0) throw Error(no_measurement_reason(n, samples, map, *map_path));
      if (n.scores.scored == 0)
        throw Error(*data +
                    ": no true position is usable to score the navigation (lat, lon, "
                    "alt and the attitude not finite, at a pole or out of range in " +
                    std::to_string(n.scores.invalid_truth) + " of " +
                    std::to_string(n.scores.rows) + " rows)");
      rows.push_back(std::move(n));
    };
    nlohmann::json online_json;
    if (*online) {
      const Model model = load_model_yaml(*model_path);
      const Model prior = prior_path->empty() ? model : load_model_yaml(*prior_path);
      nav::CoefficientPriorSettings ps;
      ps.cold = *cold;
      ps.walk_share_per_sqrt_h = *coef_walk;
      nav::FilterSettings online_settings = settings;
      nav::set_coefficient_prior(model, &prior, ps, &online_settings);
      const nav::OnlineMeasurement om = nav::online_measurement(f, model);
      main_anomaly = om.raw_anomaly_nT;
      navigate("",
               *cold ? "online (cold)"
                     : "online (prior " + (prior_path->empty() ? *model_path : *prior_path) + ")",
               om.raw_anomaly_nT, std::nullopt, &om, &online_settings);
      const Navigated& n = rows.back();
      const Eigen::VectorXd learned = n.run.steps.back().coefficients;
      online_json = learned_json(
          nav::learned_coefficients(model, online_settings, learned, n.run.coefficient_covariance),
          *cold ? "cold" : (prior_path->empty() ? *model_path : *prior_path));
      if (!out_model->empty()) {
        // Once flown: the whole flight re-fitted against the map at the filter's positions.
        Eigen::VectorXd lat(static_cast<Eigen::Index>(n.run.steps.size())), lon(lat.size());
        for (size_t k = 0; k < n.run.steps.size(); ++k) {
          lat[static_cast<Eigen::Index>(k)] = n.run.steps[k].lat_rad;
          lon[static_cast<Eigen::Index>(k)] = n.run.steps[k].lon_rad;
        }
        const nav::SmoothedCoefficients sm = nav::smoothed_coefficients(
            om, n.run.rows, lat, lon, map, learned, n.run.coefficient_covariance);
        Model out = nav::learned_model(model, sm.coefficients, sm.covariance);
        out.report.estimates.push_back("coefficients learned online in the navigation filter on " +
                                       *data + " against the map " + *map_path +
                                       ", then re-fitted over the " + std::to_string(sm.rows) +
                                       " samples on the map at the filter's positions");
        online_json["smoothed"] = {{"rows", sm.rows},
                                   {"residual_std_nT", json_figure(sm.residual_std_nT)}};
        save_model_yaml(out, *out_model, guard.input_paths());
      }
      if (model.fitted())
        navigate("static", *model_path + " (as given)", anomaly_of(f, *model_path, ""),
                 r_of(*model_path));
    } else {
      main_anomaly = anomaly_of(f, *model_path, *anomaly_field);
      navigate("", anomaly_field->empty() ? *model_path : *anomaly_field, main_anomaly,
               model_path->empty() ? std::nullopt : r_of(*model_path));
    }
    if (!baseline->empty())
      navigate("baseline", *baseline, anomaly_of(f, *baseline, ""), r_of(*baseline));
    if (!model_path->empty())
      navigate("uncompensated", "uncompensated", anomaly_of(f, *model_path, "", true),
               std::nullopt);
    guard.check_inputs_unchanged();

    const Navigated& first = rows.front();
    if (cold_start) {
      const double t0 = samples.ins.empty() ? 0.0 : samples.ins.front().t_s;
      if (std::isfinite(first.run.handover_t_s)) {
        const auto [after_m, bound_m] =
            drms_after(first.run, bound, samples, first.run.handover_t_s);
        std::printf(
            "cold start: %d particles from %.0f m; handed over to the EKF after %.1f s; "
            "from then on DRMS %.1f m (CRLB %.1f m)\n",
            cold_start->particles, cold_start->init_sigma_m, first.run.handover_t_s - t0, after_m,
            bound_m);
      } else
        std::printf(
            "warning: cold start: %d particles from %.0f m never gathered below %.0f m: the "
            "particle filter navigated the whole flight\n",
            cold_start->particles, cold_start->init_sigma_m, cold_start->handover_sigma_m);
    }
    std::printf("%s: %ld samples at %.3g s, map %ldx%ld cells at %.0f m\n", data->c_str(),
                static_cast<long>(f.size()), samples.dt_s, static_cast<long>(map.map_nT.rows()),
                static_cast<long>(map.map_nT.cols()), map.alt_m);
    std::printf("%-32s %12s %11s %9s %10s %12s %16s %10s\n", "measurement", "meas-map nT",
                "filter m", "INS m", "CRLB m", "NEES in 95%", "innovation nT", "used");
    for (const Navigated& n : rows) {
      const nav::NavigationScores& s = n.scores;
      const std::string innov =
          figure(s.innovation_mean_nT, "%.2f") + " +- " + figure(s.innovation_std_nT, "%.2f");
      std::printf("%-32s %12s %11s %9s %10s %12s %16s %10ld\n", n.name.c_str(),
                  figure(s.measurement_minus_map_std_nT, "%.3f").c_str(),
                  figure(s.drms_filter_m, "%.1f").c_str(), figure(s.drms_ins_m, "%.1f").c_str(),
                  figure(s.drms_crlb_m, "%.1f").c_str(),
                  figure(100 * s.nees_in_bounds, "%.0f%%").c_str(), innov.c_str(), s.updates);
    }
    // What the figures come from, and every fault met on the way.
    const nav::NavigationScores& s0 = first.scores;
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
    nlohmann::json j = to_json(first.scores);
    j["data"] = *data;
    j["map"] = *map_path;
    j["measurement"] = first.name;
    if (cold_start) {
      const double t0 = samples.ins.empty() ? 0.0 : samples.ins.front().t_s;
      const auto [after_m, bound_m] = drms_after(first.run, bound, samples, first.run.handover_t_s);
      j["cold_start"] = {{"particles", cold_start->particles},
                         {"init_sigma_m", cold_start->init_sigma_m},
                         {"handover_after_s", json_figure(first.run.handover_t_s - t0)},
                         {"drms_after_handover_m", json_figure(after_m)},
                         {"crlb_after_handover_m", json_figure(bound_m)}};
    }
    for (size_t k = 1; k < rows.size(); ++k) {
      nlohmann::json& r = j[rows[k].key];
      r = to_json(rows[k].scores);
      if (rows[k].key == "baseline") r["model"] = *baseline;
    }
    if (*online) {
      j["online"] = online_json;
      print_learned(online_json);
    }
    if (!json_path->empty()) write_file_atomic(*json_path, j.dump(2) + "\n", guard.input_paths());
    if (!report->empty())
      write_report(*report, samples, first, main_anomaly, map, j, guard.input_paths());
  });
}

}  // namespace magcomp::cli
