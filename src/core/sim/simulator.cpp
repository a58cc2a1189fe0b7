// magcomp simulator: assembly of the Earth field, the aircraft, the sensors and the hidden effects
// (the steps in simulator_steps.h; the sensors in simulator_sensors.cpp, the navigation map and
// INS in simulator_navigation.cpp).
#include "magcomp/core/sim/simulator.h"

#include <unistd.h>
#include <yaml-cpp/yaml.h>

#include <Eigen/Geometry>
#include <cmath>
#include <cstdio>
#include <fstream>
#include <functional>
#include <limits>
#include <map>
#include <random>

#include "magcomp/core/error.h"
#include "magcomp/core/geo/igrf.h"
#include "magcomp/core/geo/potential_field.h"
#include "magcomp/core/io/file_io.h"
#include "magcomp/core/io/time_base.h"
#include "magcomp/core/math/timeseries.h"
#include "magcomp/core/model/signal.h"
#include "magcomp/core/nav/nav_model.h"
#include "magcomp/core/nav/pinson.h"
#include "magcomp/core/sim/crustal_field.h"
#include "magcomp/core/sim/electrical.h"
#include "magcomp/core/sim/trajectory.h"
#include "simulator_steps.h"

namespace magcomp::sim {

std::string truth_path(const std::string& out_h5, const std::string& extension) {
  std::string base = out_h5;
  if (base.size() > 3 && base.substr(base.size() - 3) == ".h5") base.resize(base.size() - 3);
  return base + ".truth." + extension;
}

std::string map_path(const std::string& out_h5) {
  std::string base = out_h5;
  if (base.size() > 3 && base.substr(base.size() - 3) == ".h5") base.resize(base.size() - 3);
  return base + ".map.h5";
}

namespace steps {

void Simulator::earth_field() {
  // IGRF every second, interpolated; the crustal anomaly and the diurnal along B̂.
  EarthAlongTrack& e = earth_;
  e.tt = tr_.t_s.array() + s_.start_tt_s;
  const Igrf& igrf = igrf_;
  const Eigen::Index step = std::max<Eigen::Index>(1, static_cast<Eigen::Index>(s_.sample_rate_hz));
  Vectors igrf_ned(static_cast<size_t>(n_));
  auto igrf_at = [&](Eigen::Index i) {
    const double year = decimal_year(s_.year, s_.doy, e.tt[i]);
    const FieldNED f = igrf.geodetic(tr_.lat_deg[i], tr_.lon_deg[i], tr_.alt_m[i], year);
    return Eigen::Vector3d(f.north_nT, f.east_nT, f.down_nT);
  };
  for (Eigen::Index i0 = 0; i0 < n_; i0 += step) {
    const Eigen::Index i1 = std::min(i0 + step, n_ - 1);
    const Eigen::Vector3d a = igrf_at(i0), b = igrf_at(i1);
    for (Eigen::Index i = i0; i <= i1; ++i) {
      const double w = i1 > i0 ? static_cast<double>(i - i0) / static_cast<double>(i1 - i0) : 0.0;
      igrf_ned[static_cast<size_t>(i)] = (1 - w) * a + w * b;
    }
  }
  const Eigen::MatrixXd ground = random_ground_anomaly(
      s_.anomaly_grid_n, s_.anomaly_grid_m, s_.anomaly_rms_nT, s_.anomaly_spectral_slope, s_.seed);
  const double h_min = tr_.alt_m.minCoeff() - s_.terrain_m;
  const double h_max = tr_.alt_m.maxCoeff() - s_.terrain_m;
  const LayeredMap layers(ground, s_.anomaly_grid_m, h_min, h_max, 100.0);
  if (s_.nav_map) navigation_map(ground);
  e.anomaly.resize(n_);
  e.diurnal.resize(n_);
  e.igrf_total.resize(n_);
  e.earth_total.resize(n_);
  const double phase = 2 * M_PI * std::uniform_real_distribution<double>(0, 1)(rng_);
  double walk = 0;
  e.body.resize(static_cast<size_t>(n_));
  for (Eigen::Index i = 0; i < n_; ++i) {
    e.anomaly[i] = layers.at(tr_.north_m[i], tr_.east_m[i], tr_.alt_m[i] - s_.terrain_m);
    walk = 0.9995 * walk + 0.02 * normal_(rng_);
    e.diurnal[i] =
        s_.diurnal_amplitude_nT * (std::sin(2 * M_PI * e.tt[i] / 86400.0 + phase) +
                                   0.3 * std::sin(4 * M_PI * e.tt[i] / 86400.0 + 2 * phase)) +
        walk * s_.diurnal_amplitude_nT / 15.0;
    const Eigen::Vector3d& g = igrf_ned[static_cast<size_t>(i)];
    e.igrf_total[i] = g.norm();
    const Eigen::Vector3d b_ned = g + (e.anomaly[i] + e.diurnal[i]) * g / g.norm();
    e.earth_total[i] = b_ned.norm();
    const Eigen::Matrix3d r_nb = (Eigen::AngleAxisd(tr_.yaw_rad[i], Eigen::Vector3d::UnitZ()) *
                                  Eigen::AngleAxisd(tr_.pitch_rad[i], Eigen::Vector3d::UnitY()) *
                                  Eigen::AngleAxisd(tr_.roll_rad[i], Eigen::Vector3d::UnitX()))
                                     .toRotationMatrix();
    const Eigen::Vector3d frd = r_nb.transpose() * b_ned;
    e.body[static_cast<size_t>(i)] = Eigen::Vector3d(frd.x(), -frd.y(), -frd.z());  // to FLU
  }
  e.rate.resize(static_cast<size_t>(n_));
  for (Eigen::Index i = 0; i < n_; ++i) {
    const Eigen::Index a = std::max<Eigen::Index>(i - 1, 0),
                       b = std::min<Eigen::Index>(i + 1, n_ - 1);
    e.rate[static_cast<size_t>(i)] =
        (e.body[static_cast<size_t>(b)] - e.body[static_cast<size_t>(a)]) /
        (static_cast<double>(std::max<Eigen::Index>(b - a, 1)) * dt_);
  }
}

std::map<std::string, Eigen::VectorXd> Simulator::ins_quantities() const {
  // The INS quantities a hidden effect may follow (no random draw).
  Eigen::VectorXd unwrapped_yaw = tr_.yaw_rad;
  for (Eigen::Index i = 1; i < n_; ++i) {
    unwrapped_yaw[i] =
        unwrapped_yaw[i - 1] + std::remainder(tr_.yaw_rad[i] - tr_.yaw_rad[i - 1], 2 * M_PI);
  }
  std::map<std::string, Eigen::VectorXd> ins;
  ins["pitch_rate"] = central_rate(tr_.pitch_rad, dt_) / kDegToRad;
  ins["roll_rate"] = central_rate(tr_.roll_rad, dt_) / kDegToRad;
  ins["yaw_rate"] = central_rate(unwrapped_yaw, dt_) / kDegToRad;
  const Eigen::VectorXd acc_fwd = central_rate(tr_.speed_mps, dt_);
  const Eigen::VectorXd acc_up = central_rate(tr_.vu_mps, dt_);
  const Eigen::VectorXd turn = central_rate(unwrapped_yaw, dt_);
  ins["ins_acc_x"] = acc_fwd;
  ins["ins_acc_y"] = (turn.array() * tr_.speed_mps.array()).matrix();
  ins["ins_acc_z"] = (acc_up.array() + kStandardGravity_mps2).matrix();
  ins["lgtl_acc"] = acc_fwd / kStandardGravity_mps2;
  ins["ltrl_acc"] = Eigen::VectorXd::Zero(n_);
  ins["nrml_acc"] =
      ((1.0 / tr_.roll_rad.array().cos() - 1.0) + acc_up.array() / kStandardGravity_mps2).matrix();
  return ins;
}

void Simulator::begin_truth() {
  FlightData& f = sim_.flight;
  FlightData& truth = sim_.truth;
  f.set_source("simulated:" + s_.source);
  f.set("tt", earth_.tt);
  truth.set("tt", earth_.tt);
  truth.set("earth_total", earth_.earth_total);
  truth.set("igrf_total", earth_.igrf_total);
  truth.set("anomaly", earth_.anomaly);
  y_.SetDoublePrecision(8);
  y_ << YAML::BeginMap;
  y_ << YAML::Key << "scenario" << YAML::Value << s_.source;
  y_ << YAML::Key << "seed" << YAML::Value << s_.seed;
  y_ << YAML::Key << "samples" << YAML::Value << static_cast<long long>(n_);
  y_ << YAML::Key << "truth_field" << YAML::Value << "mag_1_c"
     << YAML::Comment("= Earth total field at the aircraft + cesium noise");
  y_ << YAML::Key << "noise" << YAML::Value << YAML::BeginMap;
  y_ << YAML::Key << "scalar_nT" << YAML::Value << s_.scalar_noise_nT;
  y_ << YAML::Key << "fluxgate_nT" << YAML::Value << s_.fluxgate_noise_nT;
  y_ << YAML::EndMap;
  y_ << YAML::Key << "earth" << YAML::Value << YAML::BeginMap;
  y_ << YAML::Key << "anomaly_rms_at_flight_nT" << YAML::Value << rms(earth_.anomaly);
  y_ << YAML::Key << "diurnal_std_nT" << YAML::Value << stdev(earth_.diurnal);
  y_ << YAML::EndMap;
}

void Simulator::draw_aircraft() {
  std::mt19937_64 aircraft_rng(static_cast<unsigned long long>(s_.aircraft_seed) * 40503ULL + 7);
  std::mt19937_64& arng = s_.aircraft_seed >= 0 ? aircraft_rng : rng_;
  // Its own distribution: normal_distribution caches values between calls, which must not leak
  // from the flight's stream into the aircraft's.
  std::normal_distribution<double> anormal(0.0, 1.0);
  std::normal_distribution<double>& an = s_.aircraft_seed >= 0 ? anormal : normal_;
  for (const SensorMount& m : sensor_mounts()) {
    const double w = m.aircraft_weight * s_.aircraft_scale;
    AircraftField a;
    for (int k = 0; k < 3; ++k) a.permanent_nT[k] = w * 200.0 * an(arng);
    for (int r = 0; r < 3; ++r)
      for (int c = 0; c < 3; ++c) a.induced(r, c) = w * 0.004 * an(arng);
    for (int r = 0; r < 3; ++r)
      for (int c = 0; c < 3; ++c) a.eddy_s(r, c) = w * 0.0008 * an(arng);
    aircraft_.push_back(a);
  }
}

void Simulator::hidden_effects_truth() {
  y_ << YAML::Key << "hidden_effects" << YAML::Value << YAML::BeginSeq;
  for (size_t k = 0; k < s_.hidden.size(); ++k) {
    y_ << YAML::BeginMap << YAML::Key << "index" << YAML::Value << static_cast<int>(k);
    hidden_effect_truth(s_.hidden[k]);
    y_ << YAML::EndMap;
  }
  y_ << YAML::EndSeq;
  y_ << YAML::EndMap;
  sim_.truth_yaml = std::string("# magcomp simulation truth\n") + y_.c_str() + "\n";
}

void Simulator::hidden_effect_truth(const HiddenEffect& e) {
  YAML::Emitter& y = y_;
  y << YAML::Key << "type" << YAML::Value << e.type;
  if (!e.channel.empty()) y << YAML::Key << "channel" << YAML::Value << e.channel;
  if (e.type == "wire") {
    y << YAML::Key << "position_m" << YAML::Value << YAML::Flow
      << std::vector<double>{e.position_m.x(), e.position_m.y(), e.position_m.z()};
    y << YAML::Key << "length_m" << YAML::Value << e.length_m;
  }
  if (e.type == "lag") y << YAML::Key << "lag_s" << YAML::Value << e.lag_s;
  if (e.type == "heading" || e.type == "drift" || e.type == "inductive" || e.type == "thermal" ||
      e.type == "flex" || e.type == "relay" || e.type == "eddy_decay" || e.type == "ripple" ||
      e.type == "product" || e.type == "hysteresis" || e.type == "saturation") {
    y << YAML::Key << "gain" << YAML::Value << e.gain;
  }
  if (e.type == "thermal" || e.type == "drift" || e.type == "eddy_decay" ||
      (e.type == "flex" && e.time_constant_s > 0)) {
    y << YAML::Key << "time_constant_s" << YAML::Value << e.time_constant_s;
  }
  if (e.type == "thermal") y << YAML::Key << "exponent" << YAML::Value << e.exponent;
  if (e.type == "hysteresis") y << YAML::Key << "half_width" << YAML::Value << e.threshold;
  if (e.type == "product") y << YAML::Key << "channel2" << YAML::Value << e.channel2;
  if (e.type == "ripple") {
    y << YAML::Key << "frequency_hz" << YAML::Value << e.frequency_hz;
    y << YAML::Key << "phase_walk_rad" << YAML::Value << e.phase_walk_rad;
  }
  if (e.type == "saturation") {
    y << YAML::Key << "dead_band_end" << YAML::Value << e.threshold;
    y << YAML::Key << "level" << YAML::Value << e.level;
  }
  if (e.type == "relay") y << YAML::Key << "threshold" << YAML::Value << e.threshold;
  const std::string term = expected_term(e);
  if (!term.empty()) {
    y << YAML::Key << "expected_term" << YAML::Value << term;
  } else if (e.type == "ripple") {
    y << YAML::Key << "expected_term" << YAML::Value
      << "(none: a ripple whose amplitude follows " + e.channel +
             " and whose phase no channel records)";
  } else if (e.type == "saturation") {
    y << YAML::Key << "expected_term" << YAML::Value
      << "(none in closed form: a dead band below " + format_param(e.threshold) + " of " +
             e.channel + ", then a core saturating at " + format_param(e.level) +
             "; a learned law of " + e.channel + ")";
  }
}

void Simulator::reference_and_survey_fields() {
  // The reference stinger (mag_1_c: compensated by the survey company), positions, altitudes.
  FlightData& f = sim_.flight;
  const Eigen::Index n = n_;
  Eigen::VectorXd mag1c(n);
  for (Eigen::Index i = 0; i < n; ++i)
    mag1c[i] = earth_.earth_total[i] + s_.scalar_noise_nT * normal_(rng_);
  f.set("mag_1_c", mag1c);
  f.set("mag_1_lag", mag1c);
  f.set("mag_1_dc", mag1c - earth_.diurnal);
  f.set("mag_1_igrf", mag1c - earth_.diurnal - earth_.igrf_total);
  f.set("diurnal", earth_.diurnal);
  f.set("line", tr_.line);
  f.set("flight", Eigen::VectorXd::Constant(n, std::floor(s_.flight)));
  f.set("year", Eigen::VectorXd::Constant(n, s_.year));
  f.set("doy", Eigen::VectorXd::Constant(n, s_.doy));
  f.set("lat", tr_.lat_deg);
  f.set("lon", tr_.lon_deg);
  f.set("utm_x", (445000.0 + tr_.east_m.array()).matrix());
  f.set("utm_y", (5020000.0 + tr_.north_m.array()).matrix());
  f.set("utm_z", tr_.alt_m);
  const double geoid_m = -33.5;  // EGM2008 undulation near Ottawa: msl = h - N
  const Eigen::VectorXd msl = tr_.alt_m.array() - geoid_m;
  f.set("msl", msl);
  Eigen::VectorXd baro(n), topo(n), radar(n);
  for (Eigen::Index i = 0; i < n; ++i) {
    topo[i] = s_.terrain_m - geoid_m +
              15.0 * std::sin(tr_.north_m[i] / 3000.0) * std::cos(tr_.east_m[i] / 4000.0);
    baro[i] = msl[i] + 6.0 + 0.5 * normal_(rng_);
    radar[i] = msl[i] - topo[i] + 0.3 * normal_(rng_);
  }
  f.set("baro", baro);
  f.set("topo", topo);
  f.set("dem", topo);
  f.set("radar", radar);
  const double nan = std::numeric_limits<double>::quiet_NaN();
  f.set("drape", Eigen::VectorXd::Constant(n, nan));
  f.set("ogs_mag", Eigen::VectorXd::Constant(n, nan));
  f.set("ogs_alt", Eigen::VectorXd::Constant(n, nan));
  ins_fields();
  Eigen::VectorXd static_p(n), pitot_p(n), total_p(n);
  for (Eigen::Index i = 0; i < n; ++i) {
    static_p[i] = 101.325 * std::pow(1 - 2.25577e-5 * msl[i], 5.25588);  // ISA, kPa
    const double rho = 1.225 * std::pow(1 - 2.25577e-5 * msl[i], 4.25588);
    pitot_p[i] = 0.5 * rho * tr_.speed_mps[i] * tr_.speed_mps[i] / 1000.0;
    total_p[i] = static_p[i] + pitot_p[i];
  }
  f.set("static_p", static_p);
  f.set("pitot_p", pitot_p);
  f.set("total_p", total_p);
  for (const std::string& c : simulated_channels()) f.set(c, channels_.at(c));
  if (s_.aircraft_states)
    for (const std::string& c : simulated_state_channels()) f.set(c, channels_.at(c));
}

void Simulator::ins_fields() {
  FlightData& f = sim_.flight;
  Eigen::VectorXd yaw_deg(n_);
  for (Eigen::Index i = 0; i < n_; ++i)
    yaw_deg[i] = std::fmod(tr_.yaw_rad[i] / kDegToRad + 360.0, 360.0);
  f.set("ins_pitch", tr_.pitch_rad / kDegToRad);
  f.set("ins_roll", tr_.roll_rad / kDegToRad);
  f.set("ins_yaw", yaw_deg);
  f.set("pitch_rate", ins_.at("pitch_rate"));
  f.set("roll_rate", ins_.at("roll_rate"));
  f.set("yaw_rate", ins_.at("yaw_rate"));
  f.set("ins_vn", tr_.vn_mps);
  f.set("ins_vw", -tr_.ve_mps);
  f.set("ins_vu", tr_.vu_mps);
  f.set("ins_lat", tr_.lat_deg * kDegToRad);
  f.set("ins_lon", tr_.lon_deg * kDegToRad);
  f.set("ins_alt", tr_.alt_m);
  f.set("ins_wander", Eigen::VectorXd::Zero(n_));
  for (const char* k : {"ins_acc_x", "ins_acc_y", "ins_acc_z", "lgtl_acc", "ltrl_acc", "nrml_acc"})
    f.set(k, ins_.at(k));
  f.set("tas", tr_.speed_mps);
}

}  // namespace steps

std::string expected_term(const HiddenEffect& e) {
  const std::string lp = "|lp(" + format_param(e.time_constant_s) + ")";
  if (e.type == "wire") return "current:" + e.channel;
  if (e.type == "inductive") return "dcurrent:" + e.channel;
  if (e.type == "lag") return "lag:" + format_param(e.lag_s);
  // |x|^exponent: a square is the signed power; any other exponent takes the magnitude first.
  if (e.type == "thermal")
    return "field:" + e.channel +
           (e.exponent == 2.0 ? std::string("|pow(2)")
                              : "|abs|pow(" + format_param(e.exponent) + ")") +
           lp;
  if (e.type == "flex") return "field:" + e.channel + (e.time_constant_s > 0 ? lp : "");
  if (e.type == "eddy_decay") return "field:B|decay(" + format_param(e.time_constant_s) + ")";
  if (e.type == "hysteresis")
    return "field:" + e.channel + "|play(" + format_param(e.threshold) + ")";
  if (e.type == "product") return "field:" + e.channel + "*" + e.channel2;
  if (e.type == "relay") return "field:" + e.channel + "|step(" + format_param(e.threshold) + ")";
  if (e.type == "drift") return "scalar:" + e.channel + lp;  // its start value is a constant
  return "";
}

Simulation simulate(const Scenario& s, const Igrf& igrf) { return steps::Simulator(s, igrf).run(); }

void write_simulation(const Simulation& sim, const std::string& out_h5,
                      const std::vector<std::string>& inputs) {
  const std::string truth_h5 = truth_path(out_h5, "h5"), truth_yaml = truth_path(out_h5, "yaml");
  for (const std::string& p : {out_h5, truth_h5, truth_yaml}) check_output_path(p, inputs);
  write_flight_h5(sim.flight, out_h5, inputs);
  write_flight_h5(sim.truth, truth_h5, inputs);
  write_file_atomic(truth_yaml, sim.truth_yaml, inputs);
  if (sim.map.map_nT.size() > 0) nav::write_anomaly_map(sim.map, map_path(out_h5), inputs);
}

}  // namespace magcomp::sim
