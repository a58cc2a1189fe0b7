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
#include "magcomp/core/math/constants.h"
#include "magcomp/core/model/model.h"
#include "magcomp/core/nav/anomaly_map.h"
#include "magcomp/core/nav/ekf.h"
#include "magcomp/core/nav/flight_navigation.h"
#include "magcomp/core/nav/nav_model.h"
#include "subcommands.h"

namespace magcomp::cli {
namespace {

// 95 % bounds of a chi-square with 2 degrees of freedom (one sample): the horizontal NEES.
constexpr double kNees2Low = 0.0506356, kNees2High = 7.37776;

struct Scores {
  double meas_vs_map_nT = NAN;  // std of the measurement minus the map at the true position
  double drms_filter_m = NAN, drms_ins_m = NAN, drms_crlb_m = NAN;
  double nees_in_bounds = NAN;  // share of samples whose horizontal NEES is in its 95 % bounds
  double innovation_mean_nT = NAN, innovation_std_nT = NAN, nis_mean = NAN;
};

// The per-sample series of one run, for the report.
struct Series {
  nav::FilterResult filter;
  nav::PositionErrors errors, ins_errors;
  Eigen::VectorXd anomaly_nT;
};

Scores navigate_once(const nav::NavTrack& ins, const nav::NavTrack& truth,
                     const Eigen::VectorXd& anomaly_nT, const nav::AnomalyMap& map,
                     const nav::FilterSettings& settings, Series* series = nullptr,
                     const Eigen::VectorXd* r_nT2 = nullptr) {
  Scores s;
  const Eigen::Index n = ins.size();
  double sum = 0, sum2 = 0;
  long used = 0;
  for (Eigen::Index i = 0; i < n; ++i) {
    const double d = anomaly_nT[i] - map.value(truth.lat_rad[i], truth.lon_rad[i]);
    if (!std::isfinite(d)) continue;
    sum += d;
    sum2 += d * d;
    ++used;
  }
  if (used == 0) throw Error("navigate: no finite anomaly sample to navigate on");
  s.meas_vs_map_nT = std::sqrt(std::max(0.0, sum2 / used - (sum / used) * (sum / used)));
  const nav::FilterResult r = nav::run_ekf(ins, anomaly_nT, map, settings, r_nT2);
  const nav::PositionErrors e = nav::position_errors(ins, r.x, truth.lat_rad, truth.lon_rad);
  s.drms_filter_m = e.drms_m;
  s.drms_ins_m = nav::position_errors(ins, {}, truth.lat_rad, truth.lon_rad).drms_m;
  s.drms_crlb_m = nav::covariance_drms_m(nav::crlb(truth, map, settings), truth.lat_rad);
  long inside = 0, updates = 0;
  double nis = 0, innovation = 0, innovation2 = 0;
  for (Eigen::Index i = 0; i < n; ++i) {
    // Horizontal position covariance in m^2 (latitude and longitude errors to north and east).
    const double lat = truth.lat_rad[i];
    const double kn = nav::dlat_to_north_m(1.0, lat), ke = nav::dlon_to_east_m(1.0, lat);
    const Eigen::MatrixXd& p = r.p[static_cast<size_t>(i)];
    Eigen::Matrix2d c;
    c << kn * kn * p(0, 0), kn * ke * p(0, 1), kn * ke * p(1, 0), ke * ke * p(1, 1);
    const Eigen::Vector2d err(e.north_m[i], e.east_m[i]);
    const double nees = err.dot(c.ldlt().solve(err));
    inside += nees >= kNees2Low && nees <= kNees2High;
    const double v = r.innovation_nT[i];
    if (!std::isfinite(v)) continue;
    nis += v * v / r.innovation_var_nT2[i];
    innovation += v;
    innovation2 += v * v;
    ++updates;
  }
  s.nees_in_bounds = static_cast<double>(inside) / static_cast<double>(n);
  s.innovation_mean_nT = innovation / static_cast<double>(updates);
  s.innovation_std_nT =
      std::sqrt(std::max(0.0, innovation2 / updates - s.innovation_mean_nT * s.innovation_mean_nT));
  s.nis_mean = nis / static_cast<double>(updates);
  if (series) {
    series->errors = e;
    series->ins_errors = nav::position_errors(ins, {}, truth.lat_rad, truth.lon_rad);
    series->anomaly_nT = anomaly_nT;
    series->filter = r;
  }
  return s;
}

nlohmann::json to_json(const Scores& s) {
  return {{"measurement_minus_map_std_nT", s.meas_vs_map_nT},
          {"drms_filter_m", s.drms_filter_m},
          {"drms_ins_m", s.drms_ins_m},
          {"drms_crlb_m", s.drms_crlb_m},
          {"nees_in_95_bounds", s.nees_in_bounds},
          {"innovation_mean_nT", s.innovation_mean_nT},
          {"innovation_std_nT", s.innovation_std_nT},
          {"nis_mean", s.nis_mean}};
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

H5Array array_of(const Eigen::VectorXd& v) {
  H5Array a;
  a.dims = {static_cast<size_t>(v.size())};
  a.values.assign(v.data(), v.data() + v.size());
  return a;
}

// DIR/tracks.h5 (truth, INS and filter tracks in degrees, errors and the filter's horizontal
// covariance in metres, innovations; the map), DIR/navigation.json, then the page.
void write_report(const std::string& dir, const nav::NavTrack& truth, const nav::NavTrack& ins,
                  const Series& s, const nav::AnomalyMap& map, const nlohmann::json& j,
                  const std::vector<std::string>& inputs) {
  make_report_dir(dir);
  const Eigen::Index n = ins.size();
  Eigen::VectorXd flat(n), flon(n), pnn(n), pee(n), pne(n), t(n);
  for (Eigen::Index i = 0; i < n; ++i) {
    t[i] = static_cast<double>(i) * ins.dt_s;
    flat[i] = (ins.lat_rad[i] + s.filter.x(0, i)) * kRadToDeg;
    flon[i] = (ins.lon_rad[i] + s.filter.x(1, i)) * kRadToDeg;
    const double kn = nav::dlat_to_north_m(1.0, truth.lat_rad[i]);
    const double ke = nav::dlon_to_east_m(1.0, truth.lat_rad[i]);
    const Eigen::MatrixXd& p = s.filter.p[static_cast<size_t>(i)];
    pnn[i] = kn * kn * p(0, 0);
    pee[i] = ke * ke * p(1, 1);
    pne[i] = kn * ke * p(0, 1);
  }
  H5Array grid;
  grid.dims = {static_cast<size_t>(map.map_nT.rows()), static_cast<size_t>(map.map_nT.cols())};
  for (Eigen::Index r = 0; r < map.map_nT.rows(); ++r)
    for (Eigen::Index c = 0; c < map.map_nT.cols(); ++c) grid.values.push_back(map.map_nT(r, c));
  write_h5_arrays(dir + "/tracks.h5",
                  {{"t_s", array_of(t)},
                   {"true_lat_deg", array_of(truth.lat_rad * kRadToDeg)},
                   {"true_lon_deg", array_of(truth.lon_rad * kRadToDeg)},
                   {"ins_lat_deg", array_of(ins.lat_rad * kRadToDeg)},
                   {"ins_lon_deg", array_of(ins.lon_rad * kRadToDeg)},
                   {"filter_lat_deg", array_of(flat)},
                   {"filter_lon_deg", array_of(flon)},
                   {"error_north_m", array_of(s.errors.north_m)},
                   {"error_east_m", array_of(s.errors.east_m)},
                   {"ins_error_north_m", array_of(s.ins_errors.north_m)},
                   {"ins_error_east_m", array_of(s.ins_errors.east_m)},
                   {"cov_north_m2", array_of(pnn)},
                   {"cov_east_m2", array_of(pee)},
                   {"cov_north_east_m2", array_of(pne)},
                   {"measurement_nT", array_of(s.anomaly_nT)},
                   {"innovation_nT", array_of(s.filter.innovation_nT)},
                   {"innovation_var_nT2", array_of(s.filter.innovation_var_nT2)},
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
  auto model_variance = std::make_shared<bool>(false);
  auto map_sigma = std::make_shared<double>(0.0);
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
  cmd->add_option("--map-sigma", *map_sigma, "the map's error std, nT, with --model-variance");
  cmd->add_option("--map-interp", *map_interp,
                  "the map's interpolation: linear (bilinear, MagNav.jl's test vectors') or cubic "
                  "(cubic convolution); default linear")
      ->check(CLI::IsMember({"linear", "cubic"}));
  cmd->add_option("--map-offset", *map_offset,
                  "'first': remove the first measurement minus the map (at the INS position) from "
                  "all measurements, the compensation's constant offset; 'none': MagNav.jl's "
                  "filter (default first)")
      ->check(CLI::IsMember({"first", "none"}));
  cmd->callback([=] {
    if (model_path->empty() == anomaly_field->empty())
      throw Error("navigate: give exactly one of --model and --anomaly");
    if (!(*meas_sigma > 0 && *fogm_sigma > 0 && *fogm_tau > 0 && *init_pos_sigma > 0))
      throw Error("navigate: --meas-sigma, --fogm-sigma, --fogm-tau, --init-pos-sigma must be > 0");
    const FlightData f = read_flight(*data);
    const double dt = f.dt_s();
    const nav::FlightTracks tracks = nav::flight_tracks(f);
    const nav::NavTrack& truth = tracks.truth;
    const nav::NavTrack& ins = tracks.ins;
    nav::AnomalyMap map = nav::read_anomaly_map(*map_path);
    if (*map_interp == "cubic") map.interpolation = nav::AnomalyMap::Interpolation::Cubic;
    if (tracks.mean_alt_m > map.alt_m + 1.0) map = nav::continued_to(map, tracks.mean_alt_m);
    nav::ModelSigmas sig;
    sig.meas_var_nT2 = *meas_sigma * *meas_sigma;
    sig.fogm_nT = *fogm_sigma;
    sig.taus.fogm_s = *fogm_tau;
    sig.init_pos_m = *init_pos_sigma;
    nav::FilterSettings settings = nav::filter_model(dt, ins.lat_rad[0], sig);
    settings.offset_from_first = *map_offset == "first";

    if (*model_variance && model_path->empty())
      throw Error("navigate: --model-variance needs --model");
    if (!(*map_sigma >= 0)) throw Error("navigate: --map-sigma must be >= 0 nT");
    // R per sample from a model: its variance plus the map's.
    auto r_of = [&](const std::string& path) -> std::optional<Eigen::VectorXd> {
      if (!*model_variance) return std::nullopt;
      Eigen::VectorXd v = compensation_variance_nT2(load_model_yaml(path), f);
      return Eigen::VectorXd(v.array() + *map_sigma * *map_sigma);
    };
    std::vector<std::pair<std::string, Scores>> rows;
    Series series;
    const auto r_main = model_path->empty() ? std::nullopt : r_of(*model_path);
    rows.emplace_back(
        anomaly_field->empty() ? *model_path : *anomaly_field,
        navigate_once(ins, truth, anomaly_of(f, *model_path, *anomaly_field), map, settings,
                      report->empty() ? nullptr : &series, r_main ? &*r_main : nullptr));
    if (!baseline->empty()) {
      const auto r_base = r_of(*baseline);
      rows.emplace_back(*baseline, navigate_once(ins, truth, anomaly_of(f, *baseline, ""), map,
                                                 settings, nullptr, r_base ? &*r_base : nullptr));
    }
    if (!model_path->empty())
      rows.emplace_back(
          "uncompensated",
          navigate_once(ins, truth, anomaly_of(f, *model_path, "", true), map, settings));
    std::printf("%s: %ld samples at %.3g s, map %ldx%ld cells at %.0f m\n", data->c_str(),
                static_cast<long>(f.size()), dt, static_cast<long>(map.map_nT.rows()),
                static_cast<long>(map.map_nT.cols()), map.alt_m);
    std::printf("%-32s %12s %11s %9s %10s %12s %16s\n", "measurement", "meas-map nT", "filter m",
                "INS m", "CRLB m", "NEES in 95%", "innovation nT");
    for (const auto& [name, s] : rows) {
      std::printf("%-32s %12.3f %11.1f %9.1f %10.1f %11.0f%% %7.2f +- %-6.2f\n", name.c_str(),
                  s.meas_vs_map_nT, s.drms_filter_m, s.drms_ins_m, s.drms_crlb_m,
                  100 * s.nees_in_bounds, s.innovation_mean_nT, s.innovation_std_nT);
    }
    nlohmann::json j = to_json(rows.front().second);
    j["data"] = *data;
    j["map"] = *map_path;
    j["measurement"] = rows.front().first;
    for (size_t k = 1; k < rows.size(); ++k) {
      const bool raw = rows[k].first == "uncompensated" && k + 1 == rows.size();
      nlohmann::json& r = j[raw ? "uncompensated" : "baseline"];
      r = to_json(rows[k].second);
      if (!raw) r["model"] = *baseline;
    }
    std::vector<std::string> inputs = {*data, *map_path};
    if (!model_path->empty()) inputs.push_back(*model_path);
    if (!json_path->empty()) write_file_atomic(*json_path, j.dump(2) + "\n", inputs);
    if (!report->empty()) write_report(*report, truth, ins, series, map, j, inputs);
  });
}

}  // namespace magcomp::cli
