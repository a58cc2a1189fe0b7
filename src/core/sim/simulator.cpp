// magcomp simulator: assembly of the Earth field, the aircraft, the sensors and the hidden effects.
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

namespace magcomp::sim {
namespace {

using Vectors = std::vector<Eigen::Vector3d>;

// Per-sensor aircraft field: B_a = p + M B + E dB/dt (body frame, nT; E in s).
struct AircraftField {
  Eigen::Vector3d permanent_nT;
  Eigen::Matrix3d induced;
  Eigen::Matrix3d eddy_s;
};

bool applies(const HiddenEffect& e, const SensorMount& m) {
  if (e.sensors.empty()) return e.type == "fluxgate" ? m.vector : !m.vector;
  return std::find(e.sensors.begin(), e.sensors.end(), m.name) != e.sensors.end();
}

double rms(const Eigen::VectorXd& v) { return std::sqrt(v.array().square().mean()); }
double stdev(const Eigen::VectorXd& v) { return std::sqrt((v.array() - v.mean()).square().mean()); }

}  // namespace

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

namespace {

// The Earth field along the track, in the body frame (FLU) and as totals, nT.
struct EarthAlongTrack {
  Eigen::VectorXd tt, anomaly, diurnal, igrf_total, earth_total;
  Vectors body;  // Earth field in base_link
  Vectors rate;  // its rate of change, nT/s
};

// One simulation's state: the steps below run in this order, and draw from one random stream in
// this order (the same seed gives the same file).
class Simulator {
 public:
  Simulator(const Scenario& s, const Igrf& igrf)
      : s_(s),
        igrf_(igrf),
        tr_(fly(s)),
        n_(tr_.size()),
        dt_(1.0 / s.sample_rate_hz),
        rng_(s.seed * 2654435761ULL + 5),
        normal_(0.0, 1.0) {}

  Simulation run() {
    earth_field();
    channels_ = simulate_channels(tr_, s_.seed);
    ins_ = ins_quantities();
    begin_truth();
    draw_aircraft();
    y_ << YAML::Key << "sensors" << YAML::Value << YAML::BeginMap;
    for (size_t k = 0; k < sensor_mounts().size(); ++k) sensor(k);
    y_ << YAML::EndMap;
    hidden_effects_truth();
    reference_and_survey_fields();
    if (s_.nav_ins_drift) drifting_ins();
    return std::move(sim_);
  }

 private:
  void earth_field();
  void navigation_map(const Eigen::MatrixXd& ground_nT);
  void drifting_ins();
  std::map<std::string, Eigen::VectorXd> ins_quantities() const;
  const Eigen::VectorXd& source(const std::string& name) const {
    auto it = channels_.find(name);
    return it != channels_.end() ? it->second : ins_.at(name);
  }
  void begin_truth();
  void draw_aircraft();
  Vectors sensor_field(const AircraftField& a) const;
  void sensor(size_t index);
  void fluxgate(const SensorMount& m, const Vectors& field);
  void scalar(const SensorMount& m, const Vectors& field);
  // One effect's contribution to a scalar sensor (nT), adding its body field to hidden_vec or
  // its scalar part to scalar_extra.
  Eigen::VectorXd hidden_contribution(const HiddenEffect& e, const SensorMount& m,
                                      const Vectors& field, Vectors* hidden_vec,
                                      Eigen::VectorXd* scalar_extra) const;
  void hidden_effects_truth();
  void hidden_effect_truth(const HiddenEffect& e);
  void reference_and_survey_fields();
  void ins_fields();

  const Scenario& s_;
  const Igrf& igrf_;  ///< the main field, given by the caller
  const Track tr_;
  const Eigen::Index n_;
  const double dt_;
  std::mt19937_64 rng_;
  std::normal_distribution<double> normal_;
  EarthAlongTrack earth_;
  std::map<std::string, Eigen::VectorXd> channels_, ins_;
  std::vector<AircraftField> aircraft_;
  Simulation sim_;
  YAML::Emitter y_;
};

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

Vectors Simulator::sensor_field(const AircraftField& a) const {
  Vectors field(static_cast<size_t>(n_));  // Earth + aircraft, body frame
  for (Eigen::Index i = 0; i < n_; ++i) {
    const auto k = static_cast<size_t>(i);
    field[k] =
        earth_.body[k] + a.permanent_nT + a.induced * earth_.body[k] + a.eddy_s * earth_.rate[k];
  }
  return field;
}

void Simulator::sensor(size_t index) {
  const SensorMount& m = sensor_mounts()[index];
  const AircraftField& a = aircraft_[index];
  const Vectors field = sensor_field(a);
  y_ << YAML::Key << m.name << YAML::Value << YAML::BeginMap;
  y_ << YAML::Key << "position_m" << YAML::Value << YAML::Flow
     << std::vector<double>{m.position_m.x(), m.position_m.y(), m.position_m.z()};
  y_ << YAML::Key << "permanent_nT" << YAML::Value << YAML::Flow
     << std::vector<double>{a.permanent_nT.x(), a.permanent_nT.y(), a.permanent_nT.z()};
  if (m.vector) {
    fluxgate(m, field);
  } else {
    scalar(m, field);
  }
  y_ << YAML::EndMap;
}

void Simulator::fluxgate(const SensorMount& m, const Vectors& field) {
  Eigen::MatrixX3d out(n_, 3), clean(n_, 3);
  for (Eigen::Index i = 0; i < n_; ++i) clean.row(i) = field[static_cast<size_t>(i)].transpose();
  out = clean;
  for (const HiddenEffect& e : s_.hidden) {
    if (e.type != "fluxgate" || !applies(e, m)) continue;
    Eigen::Matrix3d t = Eigen::Matrix3d::Identity();
    t.diagonal() += e.scale;
    t(1, 0) = std::sin(e.nonorthogonality_rad[0]);  // y axis leans toward x
    t(2, 0) = std::sin(e.nonorthogonality_rad[1]);  // z toward x
    t(2, 1) = std::sin(e.nonorthogonality_rad[2]);  // z toward y
    out = ((out * t.transpose()).rowwise() + e.offset_nT.transpose()).eval();
  }
  for (int c = 0; c < 3; ++c) {
    for (Eigen::Index i = 0; i < n_; ++i) out(i, c) += s_.fluxgate_noise_nT * normal_(rng_);
  }
  const char* axis[3] = {"_x", "_y", "_z"};
  for (int c = 0; c < 3; ++c) {
    sim_.flight.set(m.name + axis[c], out.col(c));
    sim_.truth.set(m.name + ".clean" + axis[c], clean.col(c));
  }
  sim_.flight.set(m.name + "_t", out.rowwise().norm());
}

Eigen::VectorXd Simulator::hidden_contribution(const HiddenEffect& e, const SensorMount& m,
                                               const Vectors& field, Vectors* hidden_vec,
                                               Eigen::VectorXd* scalar_extra) const {
  Eigen::VectorXd contrib(n_);
  // A body field b(t): its effect on the scalar is the exact change of the norm.
  auto body_field = [&](const std::function<Eigen::Vector3d(Eigen::Index)>& b_of) {
    for (Eigen::Index i = 0; i < n_; ++i) {
      const auto kk = static_cast<size_t>(i);
      const Eigen::Vector3d b = b_of(i);
      contrib[i] = (field[kk] + b).norm() - field[kk].norm();
      (*hidden_vec)[kk] += b;
    }
  };
  if (e.type == "wire") {
    const Eigen::Vector3d per_ampere =
        wire_field_per_ampere_nT(e.position_m - 0.5 * e.length_m * e.direction,
                                 e.position_m + 0.5 * e.length_m * e.direction, m.position_m);
    const Eigen::VectorXd& current = channels_.at(e.channel);
    body_field([&](Eigen::Index i) { return Eigen::Vector3d(per_ampere * current[i]); });
  } else if (e.type == "inductive") {
    const Eigen::VectorXd rate = central_rate(channels_.at(e.channel), dt_);
    body_field([&](Eigen::Index i) { return Eigen::Vector3d(e.gain * e.direction * rate[i]); });
  } else if (e.type == "thermal" || e.type == "flex" || e.type == "relay" ||
             e.type == "eddy_decay") {
    // b = gain · direction · s(t) (eddy_decay: gain · E · lp(dB/dt)); s low-passed by the
    // effect's time constant (none for a relay).
    const double alpha = e.time_constant_s > 0 ? std::exp(-dt_ / e.time_constant_s) : 0.0;
    static const Eigen::Matrix3d kEddyPattern =
        (Eigen::Matrix3d() << 1.0, 0.5, 0.0, 0.3, -0.8, 0.4, 0.0, 0.6, 1.0).finished();
    Eigen::Vector3d state = Eigen::Vector3d::Zero();
    body_field([&](Eigen::Index i) -> Eigen::Vector3d {
      if (e.type == "eddy_decay") {
        const Eigen::Vector3d& r = earth_.rate[static_cast<size_t>(i)];
        state = i == 0 ? r : Eigen::Vector3d(alpha * state + (1 - alpha) * r);
        return e.gain * (kEddyPattern * state);
      }
      const double x = source(e.channel)[i];
      double v = e.type == "thermal" ? std::pow(std::abs(x), e.exponent)
                 : e.type == "relay" ? (x > e.threshold ? 1.0 : 0.0)
                                     : x;
      if (e.type != "relay" && e.time_constant_s > 0) {
        state[0] = i == 0 ? v : alpha * state[0] + (1 - alpha) * v;
        v = state[0];
      }
      return e.gain * v * e.direction;
    });
  } else if (e.type == "hysteresis") {
    // A soft-iron part magnetised by a current's field, with play: the backlash operator of
    // half-width `threshold` on the current.
    const Eigen::VectorXd& x = channels_.at(e.channel);
    double state = x[0];
    body_field([&](Eigen::Index i) {
      state = std::max(x[i] - e.threshold, std::min(x[i] + e.threshold, state));
      return Eigen::Vector3d(e.gain * state * e.direction);
    });
  } else if (e.type == "saturation") {
    // A current through a core: nothing below the dead band's end, then a field that levels off.
    const Eigen::VectorXd& x = channels_.at(e.channel);
    body_field([&](Eigen::Index i) {
      const double v = e.level * std::tanh(std::max(x[i] - e.threshold, 0.0) / e.level);
      return Eigen::Vector3d(e.gain * v * e.direction);
    });
  } else if (e.type == "product") {
    const Eigen::VectorXd& x = source(e.channel);
    const Eigen::VectorXd& y = source(e.channel2);
    body_field([&](Eigen::Index i) { return Eigen::Vector3d(e.gain * x[i] * y[i] * e.direction); });
  } else if (e.type == "heading") {
    for (Eigen::Index i = 0; i < n_; ++i) {
      contrib[i] = e.gain * field[static_cast<size_t>(i)].normalized().dot(e.direction);
    }
    *scalar_extra += contrib;
  } else if (e.type == "ripple") {
    // Its own random stream (the scenario's seed and the sensor): the other fields of a
    // scenario without a ripple are unchanged.
    std::mt19937 rng(s_.seed * 2654435761u +
                     static_cast<unsigned>(std::hash<std::string>{}(m.name)));
    std::normal_distribution<double> step(0.0, e.phase_walk_rad * std::sqrt(dt_));
    const Eigen::VectorXd& x = channels_.at(e.channel);
    double phase = 0.0;
    for (Eigen::Index i = 0; i < n_; ++i) {
      phase += step(rng);
      contrib[i] = e.gain * x[i] * std::sin(2 * kPi * e.frequency_hz * dt_ * i + phase);
    }
    *scalar_extra += contrib;
  } else if (e.type == "drift") {
    const Eigen::VectorXd& x = channels_.at(e.channel);
    const double alpha = std::exp(-dt_ / e.time_constant_s);
    double state = x[0];
    for (Eigen::Index i = 0; i < n_; ++i) {
      state = alpha * state + (1 - alpha) * x[i];
      contrib[i] = e.gain * (state - x[0]);
    }
    *scalar_extra += contrib;
  }
  return contrib;
}

void Simulator::scalar(const SensorMount& m, const Vectors& field) {
  // The exact norm of Earth + aircraft + hidden body fields, then the scalar effects, the lag
  // and the noise.
  Eigen::VectorXd base(n_);
  for (Eigen::Index i = 0; i < n_; ++i) base[i] = field[static_cast<size_t>(i)].norm();
  sim_.truth.set(m.name + ".aircraft", base - earth_.earth_total);
  y_ << YAML::Key << "aircraft_rms_nT" << YAML::Value << rms(base - earth_.earth_total);
  y_ << YAML::Key << "aircraft_std_nT" << YAML::Value << stdev(base - earth_.earth_total);
  Vectors hidden_vec(static_cast<size_t>(n_), Eigen::Vector3d::Zero());
  Eigen::VectorXd scalar_extra = Eigen::VectorXd::Zero(n_);
  std::vector<std::pair<size_t, Eigen::VectorXd>> contributions;
  for (size_t k = 0; k < s_.hidden.size(); ++k) {
    const HiddenEffect& e = s_.hidden[k];
    if (!applies(e, m) || e.type == "fluxgate" || e.type == "lag") continue;
    contributions.emplace_back(k, hidden_contribution(e, m, field, &hidden_vec, &scalar_extra));
  }
  Eigen::VectorXd clean(n_);
  for (Eigen::Index i = 0; i < n_; ++i) {
    const auto kk = static_cast<size_t>(i);
    clean[i] = (field[kk] + hidden_vec[kk]).norm() + scalar_extra[i];
  }
  for (size_t k = 0; k < s_.hidden.size(); ++k) {
    const HiddenEffect& e = s_.hidden[k];
    if (e.type != "lag" || !applies(e, m)) continue;
    // Before the flight's first sample the sensor read the field of the first sample.
    const Eigen::VectorXd lagged = shift_samples(clean, e.lag_s / dt_, true);
    contributions.emplace_back(k, lagged - clean);
    clean = lagged;
  }
  Eigen::VectorXd noise(n_);
  for (Eigen::Index i = 0; i < n_; ++i) noise[i] = s_.scalar_noise_nT * normal_(rng_);
  sim_.flight.set(m.name, clean + noise);
  sim_.truth.set(m.name + ".clean", clean);
  sim_.truth.set(m.name + ".noise", noise);
  y_ << YAML::Key << "hidden" << YAML::Value << YAML::BeginSeq;
  for (const auto& [k, contrib] : contributions) {
    const std::string col = m.name + ".hidden." + std::to_string(k) + "." + s_.hidden[k].type;
    sim_.truth.set(col, contrib);
    y_ << YAML::BeginMap << YAML::Key << "effect" << YAML::Value << static_cast<int>(k) << YAML::Key
       << "type" << YAML::Value << s_.hidden[k].type << YAML::Key << "column" << YAML::Value << col
       << YAML::Key << "rms_nT" << YAML::Value << rms(contrib) << YAML::Key << "std_nT"
       << YAML::Value << stdev(contrib) << YAML::EndMap;
  }
  y_ << YAML::EndSeq;
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

// The anomaly the flight samples, as a map a navigator would carry: a latitude/longitude grid over
// the flight and a margin, at the flight's mean height above the (flat) ground, its cell the
// anomaly grid's. The flight at that height samples exactly this field.
void Simulator::navigation_map(const Eigen::MatrixXd& ground) {
  const double mean_alt = tr_.alt_m.mean();
  const double cell = s_.anomaly_grid_m, margin = s_.nav_map_margin_m;
  const Eigen::MatrixXd grid = upward_continue(ground, cell, cell, mean_alt - s_.terrain_m);
  const double n0 = tr_.north_m.minCoeff() - margin, n1 = tr_.north_m.maxCoeff() + margin;
  const double e0 = tr_.east_m.minCoeff() - margin, e1 = tr_.east_m.maxCoeff() + margin;
  const auto ny = static_cast<Eigen::Index>(std::ceil((n1 - n0) / cell)) + 1;
  const auto nx = static_cast<Eigen::Index>(std::ceil((e1 - e0) / cell)) + 1;
  const double deg_per_north_m = 1.0 / kMeanEarthRadius_m / kDegToRad;
  const double deg_per_east_m =
      1.0 / (kMeanEarthRadius_m * std::cos(s_.origin_lat_deg * kDegToRad)) / kDegToRad;
  nav::AnomalyMap& m = sim_.map;
  m.alt_m = mean_alt;
  m.lat_rad.resize(ny);
  m.lon_rad.resize(nx);
  m.map_nT.resize(ny, nx);
  m.mask = Eigen::MatrixXd::Ones(ny, nx);
  for (Eigen::Index i = 0; i < ny; ++i)
    m.lat_rad[i] = (s_.origin_lat_deg + (n0 + cell * i) * deg_per_north_m) * kDegToRad;
  for (Eigen::Index j = 0; j < nx; ++j)
    m.lon_rad[j] = (s_.origin_lon_deg + (e0 + cell * j) * deg_per_east_m) * kDegToRad;
  for (Eigen::Index i = 0; i < ny; ++i)
    for (Eigen::Index j = 0; j < nx; ++j)
      m.map_nT(i, j) = periodic_value(grid, cell, n0 + cell * i, e0 + cell * j);
}

// A navigation-grade INS: its position errors propagated with the filter's own error model
// (Pinson dynamics, MagNav.jl's default sigmas) from an initial error drawn from P0, on a random
// stream of their own. The attitude and velocities stay as recorded.
void Simulator::drifting_ins() {
  const double dt = 1.0 / s_.sample_rate_hz;
  const Eigen::VectorXd lat = tr_.lat_deg * kDegToRad, lon = tr_.lon_deg * kDegToRad;
  const nav::NavTrack truth =
      nav::track_from_positions(dt, lat, lon, tr_.alt_m, tr_.roll_rad, tr_.pitch_rad, tr_.yaw_rad);
  const nav::FilterSettings model = nav::filter_model(dt, lat[0], nav::ModelSigmas{});
  std::mt19937_64 rng(s_.nav_ins_seed * 0x9E3779B97F4A7C15ULL + s_.seed);
  std::normal_distribution<double> normal(0.0, 1.0);
  const Eigen::VectorXd sd0 = model.p0.diagonal().cwiseSqrt(),
                        sdq = model.qd.diagonal().cwiseSqrt();
  Eigen::VectorXd x(18);
  for (int k = 0; k < 18; ++k) x[k] = sd0[k] * normal(rng);
  x[17] = 0.0;  // the catch-all is the filter's, not the INS's
  Eigen::VectorXd ins_lat(n_), ins_lon(n_), ins_alt(n_);
  for (Eigen::Index i = 0; i < n_; ++i) {
    ins_lat[i] = lat[i] + x[0];
    ins_lon[i] = lon[i] + x[1];
    ins_alt[i] = tr_.alt_m[i] + x[2];
    const Eigen::MatrixXd phi = nav::pinson_transition(truth.point(i), model.taus, true, dt);
    x = phi * x;
    for (int k = 0; k < 17; ++k) x[k] += sdq[k] * normal(rng);
  }
  sim_.flight.set("ins_lat", ins_lat);
  sim_.flight.set("ins_lon", ins_lon);
  sim_.flight.set("ins_alt", ins_alt);
  const nav::PositionErrors e =
      nav::position_errors(nav::track_from_positions(dt, ins_lat, ins_lon, ins_alt, tr_.roll_rad,
                                                     tr_.pitch_rad, tr_.yaw_rad),
                           {}, lat, lon);
  char line[96];
  std::snprintf(line, sizeof(line), "ins_drift_drms_m: %.3f\n", e.drms_m);
  sim_.truth_yaml += line;
}

}  // namespace

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

Simulation simulate(const Scenario& s, const Igrf& igrf) { return Simulator(s, igrf).run(); }

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
