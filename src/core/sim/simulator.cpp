// magcomp simulator: assembly of the Earth field, the aircraft, the sensors and the hidden effects.
#include "magcomp/core/sim/simulator.h"

#include <unistd.h>
#include <yaml-cpp/yaml.h>

#include <Eigen/Geometry>
#include <cmath>
#include <cstdio>
#include <fstream>
#include <map>
#include <random>

#include "magcomp/core/error.h"
#include "magcomp/core/file_io.h"
#include "magcomp/core/igrf.h"
#include "magcomp/core/signal.h"
#include "magcomp/core/sim/anomaly_map.h"
#include "magcomp/core/sim/electrical.h"
#include "magcomp/core/sim/trajectory.h"
#include "magcomp/core/timeseries.h"

namespace magcomp::sim {
namespace {

constexpr double kDeg = M_PI / 180.0;

using Vectors = std::vector<Eigen::Vector3d>;

Eigen::VectorXd central_rate(const Eigen::VectorXd& x, double dt) {
  const Eigen::Index n = x.size();
  Eigen::VectorXd d(n);
  for (Eigen::Index i = 0; i < n; ++i) {
    const Eigen::Index a = std::max<Eigen::Index>(i - 1, 0),
                       b = std::min<Eigen::Index>(i + 1, n - 1);
    d[i] = (x[b] - x[a]) / (std::max<Eigen::Index>(b - a, 1) * dt);
  }
  return d;
}

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

Simulation simulate(const Scenario& s) {
  const Track tr = fly(s);
  const Eigen::Index n = tr.size();
  const double dt = 1.0 / s.sample_rate_hz;
  std::mt19937_64 rng(s.seed * 2654435761ULL + 5);
  std::normal_distribution<double> normal(0.0, 1.0);
  Eigen::VectorXd tt = tr.t_s.array() + s.start_tt_s;

  // --- Earth field in NED: IGRF (every second, interpolated) + anomaly + diurnal along B̂.
  const Igrf& igrf = Igrf::shipped();
  const Eigen::Index step = std::max<Eigen::Index>(1, static_cast<Eigen::Index>(s.sample_rate_hz));
  Vectors igrf_ned(static_cast<size_t>(n));
  auto igrf_at = [&](Eigen::Index i) {
    const double year = decimal_year(s.year, s.doy, tt[i]);
    const FieldNED f = igrf.geodetic(tr.lat_deg[i], tr.lon_deg[i], tr.alt_m[i], year);
    return Eigen::Vector3d(f.north_nT, f.east_nT, f.down_nT);
  };
  for (Eigen::Index i0 = 0; i0 < n; i0 += step) {
    const Eigen::Index i1 = std::min(i0 + step, n - 1);
    const Eigen::Vector3d a = igrf_at(i0), b = igrf_at(i1);
    for (Eigen::Index i = i0; i <= i1; ++i) {
      const double w = i1 > i0 ? static_cast<double>(i - i0) / static_cast<double>(i1 - i0) : 0.0;
      igrf_ned[static_cast<size_t>(i)] = (1 - w) * a + w * b;
    }
  }
  const AnomalyMap map = AnomalyMap::random(s.anomaly_grid_n, s.anomaly_grid_m, s.anomaly_rms_nT,
                                            s.anomaly_spectral_slope, s.seed);
  const double h_min = tr.alt_m.minCoeff() - s.terrain_m, h_max = tr.alt_m.maxCoeff() - s.terrain_m;
  const LayeredMap layers(map, h_min, h_max, 100.0);
  Eigen::VectorXd anomaly(n), diurnal(n), igrf_total(n), earth_total(n);
  const double phase = 2 * M_PI * std::uniform_real_distribution<double>(0, 1)(rng);
  double walk = 0;
  Vectors earth_body(static_cast<size_t>(n));
  for (Eigen::Index i = 0; i < n; ++i) {
    anomaly[i] = layers.at(tr.north_m[i], tr.east_m[i], tr.alt_m[i] - s.terrain_m);
    walk = 0.9995 * walk + 0.02 * normal(rng);
    diurnal[i] = s.diurnal_amplitude_nT * (std::sin(2 * M_PI * tt[i] / 86400.0 + phase) +
                                           0.3 * std::sin(4 * M_PI * tt[i] / 86400.0 + 2 * phase)) +
                 walk * s.diurnal_amplitude_nT / 15.0;
    const Eigen::Vector3d& g = igrf_ned[static_cast<size_t>(i)];
    igrf_total[i] = g.norm();
    const Eigen::Vector3d b_ned = g + (anomaly[i] + diurnal[i]) * g / g.norm();
    earth_total[i] = b_ned.norm();
    const Eigen::Matrix3d r_nb = (Eigen::AngleAxisd(tr.yaw_rad[i], Eigen::Vector3d::UnitZ()) *
                                  Eigen::AngleAxisd(tr.pitch_rad[i], Eigen::Vector3d::UnitY()) *
                                  Eigen::AngleAxisd(tr.roll_rad[i], Eigen::Vector3d::UnitX()))
                                     .toRotationMatrix();
    const Eigen::Vector3d frd = r_nb.transpose() * b_ned;
    earth_body[static_cast<size_t>(i)] = Eigen::Vector3d(frd.x(), -frd.y(), -frd.z());  // to FLU
  }
  Vectors earth_rate(static_cast<size_t>(n));
  for (Eigen::Index i = 0; i < n; ++i) {
    const Eigen::Index a = std::max<Eigen::Index>(i - 1, 0),
                       b = std::min<Eigen::Index>(i + 1, n - 1);
    earth_rate[static_cast<size_t>(i)] =
        (earth_body[static_cast<size_t>(b)] - earth_body[static_cast<size_t>(a)]) /
        (static_cast<double>(std::max<Eigen::Index>(b - a, 1)) * dt);
  }

  // --- Electrical channels, and the INS quantities a hidden effect may follow (no random draw).
  std::map<std::string, Eigen::VectorXd> channels = simulate_channels(tr, s.seed);
  Eigen::VectorXd unwrapped_yaw = tr.yaw_rad;
  for (Eigen::Index i = 1; i < n; ++i) {
    unwrapped_yaw[i] =
        unwrapped_yaw[i - 1] + std::remainder(tr.yaw_rad[i] - tr.yaw_rad[i - 1], 2 * M_PI);
  }
  std::map<std::string, Eigen::VectorXd> ins;
  ins["pitch_rate"] = central_rate(tr.pitch_rad, dt) / kDeg;
  ins["roll_rate"] = central_rate(tr.roll_rad, dt) / kDeg;
  ins["yaw_rate"] = central_rate(unwrapped_yaw, dt) / kDeg;
  {
    const Eigen::VectorXd acc_fwd = central_rate(tr.speed_mps, dt);
    const Eigen::VectorXd acc_up = central_rate(tr.vu_mps, dt);
    const Eigen::VectorXd turn = central_rate(unwrapped_yaw, dt);
    ins["ins_acc_x"] = acc_fwd;
    ins["ins_acc_y"] = (turn.array() * tr.speed_mps.array()).matrix();
    ins["ins_acc_z"] = (acc_up.array() + 9.80665).matrix();
    ins["lgtl_acc"] = acc_fwd / 9.80665;
    ins["ltrl_acc"] = Eigen::VectorXd::Zero(n);
    ins["nrml_acc"] =
        ((1.0 / tr.roll_rad.array().cos() - 1.0) + acc_up.array() / 9.80665).matrix();
  }
  auto source = [&](const std::string& name) -> const Eigen::VectorXd& {
    auto it = channels.find(name);
    return it != channels.end() ? it->second : ins.at(name);
  };

  Simulation sim;
  FlightData& f = sim.flight;
  FlightData& truth = sim.truth;
  f.set_source("simulated:" + s.source);
  f.set("tt", tt);
  truth.set("tt", tt);
  truth.set("earth_total", earth_total);
  truth.set("igrf_total", igrf_total);
  truth.set("anomaly", anomaly);

  YAML::Emitter y;
  y.SetDoublePrecision(8);
  y << YAML::BeginMap;
  y << YAML::Key << "scenario" << YAML::Value << s.source;
  y << YAML::Key << "seed" << YAML::Value << s.seed;
  y << YAML::Key << "samples" << YAML::Value << static_cast<long long>(n);
  y << YAML::Key << "truth_field" << YAML::Value << "mag_1_c"
    << YAML::Comment("= Earth total field at the aircraft + cesium noise");
  y << YAML::Key << "noise" << YAML::Value << YAML::BeginMap;
  y << YAML::Key << "scalar_nT" << YAML::Value << s.scalar_noise_nT;
  y << YAML::Key << "fluxgate_nT" << YAML::Value << s.fluxgate_noise_nT;
  y << YAML::EndMap;
  y << YAML::Key << "earth" << YAML::Value << YAML::BeginMap;
  y << YAML::Key << "anomaly_rms_at_flight_nT" << YAML::Value << rms(anomaly);
  y << YAML::Key << "diurnal_std_nT" << YAML::Value << stdev(diurnal);
  y << YAML::EndMap;

  // --- Sensors.
  std::vector<AircraftField> aircraft;
  std::mt19937_64 aircraft_rng(static_cast<unsigned long long>(s.aircraft_seed) * 40503ULL + 7);
  std::mt19937_64& arng = s.aircraft_seed >= 0 ? aircraft_rng : rng;
  // Its own distribution: normal_distribution caches values between calls, which must not leak
  // from the flight's stream into the aircraft's.
  std::normal_distribution<double> anormal(0.0, 1.0);
  std::normal_distribution<double>& an = s.aircraft_seed >= 0 ? anormal : normal;
  for (const SensorMount& m : sensor_mounts()) {
    const double w = m.aircraft_weight * s.aircraft_scale;
    AircraftField a;
    for (int k = 0; k < 3; ++k) a.permanent_nT[k] = w * 200.0 * an(arng);
    for (int r = 0; r < 3; ++r)
      for (int c = 0; c < 3; ++c) a.induced(r, c) = w * 0.004 * an(arng);
    for (int r = 0; r < 3; ++r)
      for (int c = 0; c < 3; ++c) a.eddy_s(r, c) = w * 0.0008 * an(arng);
    aircraft.push_back(a);
  }
  y << YAML::Key << "sensors" << YAML::Value << YAML::BeginMap;
  const auto& mounts = sensor_mounts();
  for (size_t si = 0; si < mounts.size(); ++si) {
    const SensorMount& m = mounts[si];
    const AircraftField& a = aircraft[si];
    Vectors field(static_cast<size_t>(n));  // Earth + aircraft, body frame
    for (Eigen::Index i = 0; i < n; ++i) {
      const auto k = static_cast<size_t>(i);
      field[k] =
          earth_body[k] + a.permanent_nT + a.induced * earth_body[k] + a.eddy_s * earth_rate[k];
    }
    y << YAML::Key << m.name << YAML::Value << YAML::BeginMap;
    y << YAML::Key << "position_m" << YAML::Value << YAML::Flow
      << std::vector<double>{m.position_m.x(), m.position_m.y(), m.position_m.z()};
    y << YAML::Key << "permanent_nT" << YAML::Value << YAML::Flow
      << std::vector<double>{a.permanent_nT.x(), a.permanent_nT.y(), a.permanent_nT.z()};
    if (m.vector) {
      Eigen::MatrixX3d out(n, 3), clean(n, 3);
      for (Eigen::Index i = 0; i < n; ++i) clean.row(i) = field[static_cast<size_t>(i)].transpose();
      out = clean;
      for (size_t k = 0; k < s.hidden.size(); ++k) {
        const HiddenEffect& e = s.hidden[k];
        if (e.type != "fluxgate" || !applies(e, m)) continue;
        Eigen::Matrix3d t = Eigen::Matrix3d::Identity();
        t.diagonal() += e.scale;
        t(1, 0) = std::sin(e.nonorthogonality_rad[0]);  // y axis leans toward x
        t(2, 0) = std::sin(e.nonorthogonality_rad[1]);  // z toward x
        t(2, 1) = std::sin(e.nonorthogonality_rad[2]);  // z toward y
        out = ((out * t.transpose()).rowwise() + e.offset_nT.transpose()).eval();
      }
      for (int c = 0; c < 3; ++c) {
        for (Eigen::Index i = 0; i < n; ++i) out(i, c) += s.fluxgate_noise_nT * normal(rng);
      }
      const char* axis[3] = {"_x", "_y", "_z"};
      for (int c = 0; c < 3; ++c) {
        f.set(m.name + axis[c], out.col(c));
        truth.set(m.name + ".clean" + axis[c], clean.col(c));
      }
      f.set(m.name + "_t", out.rowwise().norm());
      y << YAML::EndMap;
      continue;
    }
    // Scalar sensor: exact norm of Earth + aircraft + hidden vector fields, then scalar effects.
    Eigen::VectorXd base(n);
    for (Eigen::Index i = 0; i < n; ++i) base[i] = field[static_cast<size_t>(i)].norm();
    truth.set(m.name + ".aircraft", base - earth_total);
    y << YAML::Key << "aircraft_rms_nT" << YAML::Value << rms(base - earth_total);
    y << YAML::Key << "aircraft_std_nT" << YAML::Value << stdev(base - earth_total);
    Vectors hidden_vec(static_cast<size_t>(n), Eigen::Vector3d::Zero());
    Eigen::VectorXd scalar_extra = Eigen::VectorXd::Zero(n);
    std::vector<std::pair<size_t, Eigen::VectorXd>> contributions;
    for (size_t k = 0; k < s.hidden.size(); ++k) {
      const HiddenEffect& e = s.hidden[k];
      if (!applies(e, m) || e.type == "fluxgate" || e.type == "lag") continue;
      Eigen::VectorXd contrib(n);
      if (e.type == "wire" || e.type == "inductive") {
        const Eigen::VectorXd& current = channels.at(e.channel);
        Eigen::Vector3d per_unit;
        Eigen::VectorXd drive;
        if (e.type == "wire") {
          per_unit =
              wire_field_per_ampere_nT(e.position_m - 0.5 * e.length_m * e.direction,
                                       e.position_m + 0.5 * e.length_m * e.direction, m.position_m);
          drive = current;
        } else {
          per_unit = e.gain * e.direction;
          drive = central_rate(current, dt);
        }
        for (Eigen::Index i = 0; i < n; ++i) {
          const auto kk = static_cast<size_t>(i);
          const Eigen::Vector3d b = per_unit * drive[i];
          contrib[i] = (field[kk] + b).norm() - field[kk].norm();
          hidden_vec[kk] += b;
        }
      } else if (e.type == "thermal" || e.type == "flex" || e.type == "relay" ||
                 e.type == "eddy_decay") {
        // A body-fixed field: b = gain · direction · s(t) (eddy_decay: gain · E · lp(dB/dt)).
        const double alpha = e.time_constant_s > 0 ? std::exp(-dt / e.time_constant_s) : 0.0;
        Eigen::Vector3d state = Eigen::Vector3d::Zero();
        for (Eigen::Index i = 0; i < n; ++i) {
          const auto kk = static_cast<size_t>(i);
          Eigen::Vector3d b;
          if (e.type == "eddy_decay") {
            static const Eigen::Matrix3d kPattern =
                (Eigen::Matrix3d() << 1.0, 0.5, 0.0, 0.3, -0.8, 0.4, 0.0, 0.6, 1.0).finished();
            const Eigen::Vector3d& r = earth_rate[kk];
            state = i == 0 ? r : Eigen::Vector3d(alpha * state + (1 - alpha) * r);
            b = e.gain * (kPattern * state);
          } else {
            const double x = source(e.channel)[i];
            double v = e.type == "thermal" ? std::pow(std::abs(x), e.exponent)
                       : e.type == "relay" ? (x > e.threshold ? 1.0 : 0.0)
                                           : x;
            if (e.type != "relay" && e.time_constant_s > 0) {
              state[0] = i == 0 ? v : alpha * state[0] + (1 - alpha) * v;
              v = state[0];
            }
            b = e.gain * v * e.direction;
          }
          contrib[i] = (field[kk] + b).norm() - field[kk].norm();
          hidden_vec[kk] += b;
        }
      } else if (e.type == "heading") {
        for (Eigen::Index i = 0; i < n; ++i) {
          const auto kk = static_cast<size_t>(i);
          contrib[i] = e.gain * field[kk].normalized().dot(e.direction);
        }
        scalar_extra += contrib;
      } else if (e.type == "drift") {
        const Eigen::VectorXd& x = channels.at(e.channel);
        const double alpha = std::exp(-dt / e.time_constant_s);
        double state = x[0];
        for (Eigen::Index i = 0; i < n; ++i) {
          state = alpha * state + (1 - alpha) * x[i];
          contrib[i] = e.gain * (state - x[0]);
        }
        scalar_extra += contrib;
      }
      contributions.emplace_back(k, contrib);
    }
    Eigen::VectorXd clean(n);
    for (Eigen::Index i = 0; i < n; ++i) {
      const auto kk = static_cast<size_t>(i);
      clean[i] = (field[kk] + hidden_vec[kk]).norm() + scalar_extra[i];
    }
    for (size_t k = 0; k < s.hidden.size(); ++k) {
      const HiddenEffect& e = s.hidden[k];
      if (e.type != "lag" || !applies(e, m)) continue;
      // Before the flight's first sample the sensor read the field of the first sample.
      const Eigen::VectorXd lagged = shift_samples(clean, e.lag_s / dt, true);
      contributions.emplace_back(k, lagged - clean);
      clean = lagged;
    }
    Eigen::VectorXd noise(n);
    for (Eigen::Index i = 0; i < n; ++i) noise[i] = s.scalar_noise_nT * normal(rng);
    f.set(m.name, clean + noise);
    truth.set(m.name + ".clean", clean);
    truth.set(m.name + ".noise", noise);
    y << YAML::Key << "hidden" << YAML::Value << YAML::BeginSeq;
    for (const auto& [k, contrib] : contributions) {
      const std::string col = m.name + ".hidden." + std::to_string(k) + "." + s.hidden[k].type;
      truth.set(col, contrib);
      y << YAML::BeginMap << YAML::Key << "effect" << YAML::Value << static_cast<int>(k)
        << YAML::Key << "type" << YAML::Value << s.hidden[k].type << YAML::Key << "column"
        << YAML::Value << col << YAML::Key << "rms_nT" << YAML::Value << rms(contrib) << YAML::Key
        << "std_nT" << YAML::Value << stdev(contrib) << YAML::EndMap;
    }
    y << YAML::EndSeq;
    y << YAML::EndMap;
  }
  y << YAML::EndMap;
  y << YAML::Key << "hidden_effects" << YAML::Value << YAML::BeginSeq;
  for (size_t k = 0; k < s.hidden.size(); ++k) {
    const HiddenEffect& e = s.hidden[k];
    y << YAML::BeginMap << YAML::Key << "index" << YAML::Value << static_cast<int>(k);
    y << YAML::Key << "type" << YAML::Value << e.type;
    if (!e.channel.empty()) y << YAML::Key << "channel" << YAML::Value << e.channel;
    if (e.type == "wire") {
      y << YAML::Key << "position_m" << YAML::Value << YAML::Flow
        << std::vector<double>{e.position_m.x(), e.position_m.y(), e.position_m.z()};
      y << YAML::Key << "length_m" << YAML::Value << e.length_m;
      y << YAML::Key << "expected_term" << YAML::Value << "current:" + e.channel;
    }
    if (e.type == "inductive")
      y << YAML::Key << "expected_term" << YAML::Value << "dcurrent:" + e.channel;
    if (e.type == "lag") {
      y << YAML::Key << "lag_s" << YAML::Value << e.lag_s;
      char lag_term[64];
      std::snprintf(lag_term, sizeof(lag_term), "lag:%g", e.lag_s);
      y << YAML::Key << "expected_term" << YAML::Value << lag_term;
    }
    if (e.type == "heading" || e.type == "drift" || e.type == "inductive" ||
        e.type == "thermal" || e.type == "flex" || e.type == "relay" || e.type == "eddy_decay") {
      y << YAML::Key << "gain" << YAML::Value << e.gain;
    }
    if (e.type == "thermal" || e.type == "drift" || e.type == "eddy_decay" ||
        (e.type == "flex" && e.time_constant_s > 0)) {
      y << YAML::Key << "time_constant_s" << YAML::Value << e.time_constant_s;
    }
    const std::string lp = "|lp(" + format_param(e.time_constant_s) + ")";
    if (e.type == "thermal") {
      y << YAML::Key << "exponent" << YAML::Value << e.exponent;
      y << YAML::Key << "expected_term" << YAML::Value
        << "field:" + e.channel + "|pow(" + format_param(e.exponent) + ")" + lp;
    }
    if (e.type == "flex") {
      y << YAML::Key << "expected_term" << YAML::Value
        << "field:" + e.channel + (e.time_constant_s > 0 ? lp : "");
    }
    if (e.type == "eddy_decay") {
      y << YAML::Key << "expected_term" << YAML::Value
        << "field:B|decay(" + format_param(e.time_constant_s) + ")";
    }
    if (e.type == "relay") {
      y << YAML::Key << "threshold" << YAML::Value << e.threshold;
      y << YAML::Key << "expected_term" << YAML::Value
        << "(none: a device switched on while " + e.channel + " > " +
               format_param(e.threshold) + "; the term language has no threshold)";
    }
    y << YAML::EndMap;
  }
  y << YAML::EndSeq;
  y << YAML::EndMap;
  sim.truth_yaml = std::string("# magcomp simulation truth\n") + y.c_str() + "\n";

  // --- The reference stinger (mag_1_c: compensated by the survey company) and the rest.
  Eigen::VectorXd mag1c(n);
  for (Eigen::Index i = 0; i < n; ++i) mag1c[i] = earth_total[i] + s.scalar_noise_nT * normal(rng);
  f.set("mag_1_c", mag1c);
  f.set("mag_1_lag", mag1c);
  f.set("mag_1_dc", mag1c - diurnal);
  f.set("mag_1_igrf", mag1c - diurnal - igrf_total);
  f.set("diurnal", diurnal);
  f.set("line", tr.line);
  f.set("flight", Eigen::VectorXd::Constant(n, std::floor(s.flight)));
  f.set("year", Eigen::VectorXd::Constant(n, s.year));
  f.set("doy", Eigen::VectorXd::Constant(n, s.doy));
  f.set("lat", tr.lat_deg);
  f.set("lon", tr.lon_deg);
  f.set("utm_x", (445000.0 + tr.east_m.array()).matrix());
  f.set("utm_y", (5020000.0 + tr.north_m.array()).matrix());
  f.set("utm_z", tr.alt_m);
  const double geoid_m = -33.5;  // EGM2008 undulation near Ottawa: msl = h - N
  const Eigen::VectorXd msl = tr.alt_m.array() - geoid_m;
  f.set("msl", msl);
  Eigen::VectorXd baro(n), topo(n), radar(n);
  for (Eigen::Index i = 0; i < n; ++i) {
    topo[i] = s.terrain_m - geoid_m +
              15.0 * std::sin(tr.north_m[i] / 3000.0) * std::cos(tr.east_m[i] / 4000.0);
    baro[i] = msl[i] + 6.0 + 0.5 * normal(rng);
    radar[i] = msl[i] - topo[i] + 0.3 * normal(rng);
  }
  f.set("baro", baro);
  f.set("topo", topo);
  f.set("dem", topo);
  f.set("radar", radar);
  const double nan = std::numeric_limits<double>::quiet_NaN();
  f.set("drape", Eigen::VectorXd::Constant(n, nan));
  f.set("ogs_mag", Eigen::VectorXd::Constant(n, nan));
  f.set("ogs_alt", Eigen::VectorXd::Constant(n, nan));
  Eigen::VectorXd yaw_deg(n);
  for (Eigen::Index i = 0; i < n; ++i) {
    yaw_deg[i] = std::fmod(tr.yaw_rad[i] / kDeg + 360.0, 360.0);
  }
  f.set("ins_pitch", tr.pitch_rad / kDeg);
  f.set("ins_roll", tr.roll_rad / kDeg);
  f.set("ins_yaw", yaw_deg);
  f.set("pitch_rate", ins["pitch_rate"]);
  f.set("roll_rate", ins["roll_rate"]);
  f.set("yaw_rate", ins["yaw_rate"]);
  f.set("ins_vn", tr.vn_mps);
  f.set("ins_vw", -tr.ve_mps);
  f.set("ins_vu", tr.vu_mps);
  f.set("ins_lat", tr.lat_deg * kDeg);
  f.set("ins_lon", tr.lon_deg * kDeg);
  f.set("ins_alt", tr.alt_m);
  f.set("ins_wander", Eigen::VectorXd::Zero(n));
  for (const char* k : {"ins_acc_x", "ins_acc_y", "ins_acc_z", "lgtl_acc", "ltrl_acc", "nrml_acc"})
    f.set(k, ins[k]);
  f.set("tas", tr.speed_mps);
  Eigen::VectorXd static_p(n), pitot_p(n), total_p(n);
  for (Eigen::Index i = 0; i < n; ++i) {
    static_p[i] = 101.325 * std::pow(1 - 2.25577e-5 * msl[i], 5.25588);  // ISA, kPa
    const double rho = 1.225 * std::pow(1 - 2.25577e-5 * msl[i], 4.25588);
    pitot_p[i] = 0.5 * rho * tr.speed_mps[i] * tr.speed_mps[i] / 1000.0;
    total_p[i] = static_p[i] + pitot_p[i];
  }
  f.set("static_p", static_p);
  f.set("pitot_p", pitot_p);
  f.set("total_p", total_p);
  for (const std::string& c : simulated_channels()) f.set(c, channels.at(c));
  return sim;
}

void write_simulation(const Simulation& sim, const std::string& out_h5,
                      const std::vector<std::string>& inputs) {
  const std::string truth_h5 = truth_path(out_h5, "h5"), truth_yaml = truth_path(out_h5, "yaml");
  for (const std::string& p : {out_h5, truth_h5, truth_yaml}) check_output_path(p, inputs);
  write_flight_h5(sim.flight, out_h5, inputs);
  write_flight_h5(sim.truth, truth_h5, inputs);
  write_file_atomic(truth_yaml, sim.truth_yaml, inputs);
}

}  // namespace magcomp::sim
