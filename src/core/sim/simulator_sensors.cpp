// magcomp simulator: the sensors (scalar magnetometers and fluxgates with their errors) and the
// hidden effects each one sees (see simulator_steps.h).
#include <Eigen/Geometry>
#include <cmath>
#include <cstdio>
#include <functional>
#include <limits>

#include "magcomp/core/error.h"
#include "magcomp/core/math/timeseries.h"
#include "magcomp/core/model/signal.h"
#include "simulator_steps.h"

namespace magcomp::sim::steps {

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

}  // namespace magcomp::sim::steps
