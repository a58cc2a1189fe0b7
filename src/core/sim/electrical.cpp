// magcomp simulator: electrical channels and Biot-Savart.
#include "magcomp/core/sim/electrical.h"

#include <Eigen/Geometry>

#include <cmath>
#include <random>

#include "magcomp/core/math/timeseries.h"
#include "magcomp/core/sim/scenario.h"

namespace magcomp::sim {

Eigen::Vector3d wire_field_per_ampere_nT(const Eigen::Vector3d& a, const Eigen::Vector3d& b,
                                         const Eigen::Vector3d& p) {
  constexpr double kMu0Over4Pi_nT_m_per_A = 100.0;  // 1e-7 T m/A
  const Eigen::Vector3d l = b - a;
  const double length = l.norm();
  const Eigen::Vector3d u = l / length;
  const Eigen::Vector3d r1 = p - a;
  const Eigen::Vector3d perp = r1 - r1.dot(u) * u;  // from the wire's line to the point
  const double d = perp.norm();
  if (d < 1e-9) return Eigen::Vector3d::Zero();
  const double s1 = r1.dot(u), s2 = s1 - length;
  const double factor = s1 / std::hypot(s1, d) - s2 / std::hypot(s2, d);
  return kMu0Over4Pi_nT_m_per_A / d * factor * u.cross(perp / d);
}

namespace {

// A two-state process with exponentially distributed on and off durations (s).
Eigen::VectorXd on_off(const Eigen::VectorXd& t, double mean_on_s, double mean_off_s,
                       std::mt19937_64& rng, bool start_on = false) {
  std::exponential_distribution<double> on(1.0 / mean_on_s), off(1.0 / mean_off_s);
  Eigen::VectorXd state(t.size());
  bool is_on = start_on;
  double next = t.size() ? t[0] + (is_on ? on(rng) : off(rng)) : 0;
  for (Eigen::Index i = 0; i < t.size(); ++i) {
    while (t[i] >= next) {
      is_on = !is_on;
      next += is_on ? on(rng) : off(rng);
    }
    state[i] = is_on ? 1.0 : 0.0;
  }
  return state;
}

// First-order low-pass with time constant tau_s of x sampled at dt_s.
Eigen::VectorXd smooth(const Eigen::VectorXd& x, double tau_s, double dt_s) {
  Eigen::VectorXd y(x.size());
  const double a = std::exp(-dt_s / tau_s);
  double s = x.size() ? x[0] : 0;
  for (Eigen::Index i = 0; i < x.size(); ++i) y[i] = s = a * s + (1 - a) * x[i];
  return y;
}

// The non-electrical states (simulated_state_channels()), from their own random stream.
void add_states(const Track& tr, unsigned seed, double dt,
                std::map<std::string, Eigen::VectorXd>* c) {
  std::mt19937_64 rng(seed * 7919ULL + 29);
  std::normal_distribution<double> normal(0.0, 1.0);
  const Eigen::Index n = tr.size();
  auto noise = [&](double sigma) {
    Eigen::VectorXd v(n);
    for (Eigen::Index i = 0; i < n; ++i) v[i] = sigma * normal(rng);
    return v;
  };
  // A setting held for exponentially distributed durations (mean `hold_s`), each drawn from
  // `levels`.
  auto setting = [&](const std::vector<double>& levels, double hold_s) {
    std::exponential_distribution<double> hold(1.0 / hold_s);
    std::uniform_int_distribution<size_t> level(0, levels.size() - 1);
    Eigen::VectorXd x(n);
    double value = levels[level(rng)];
    double next = n ? tr.t_s[0] + hold(rng) : 0;
    for (Eigen::Index i = 0; i < n; ++i) {
      while (tr.t_s[i] >= next) {
        value = levels[level(rng)];
        next += hold(rng);
      }
      x[i] = value;
    }
    return x;
  };
  // Flaps: 0, 10 or 20 deg, moved by the motor over about 3 s.
  (*c)["flap_deg"] = smooth(setting({0.0, 10.0, 20.0}, 300.0), 1.5, dt) + noise(0.05);
  // Engine speed: a power setting changed now and then, the engine following in about 2 s.
  (*c)["eng_rpm"] = smooth(setting({2300.0, 2400.0, 2500.0, 2600.0}, 200.0), 2.0, dt) + noise(5.0);
  // Outside air temperature: 15 degC at sea level, 6.5 degC colder per km, the probe lagging.
  Eigen::VectorXd oat(n);
  for (Eigen::Index i = 0; i < n; ++i) oat[i] = 15.0 - 6.5e-3 * tr.alt_m[i];
  (*c)["oat_degC"] = smooth(oat, 20.0, dt) + noise(0.05);
  (*c)["sw_pitot_heat"] = on_off(tr.t_s, 400.0, 400.0, rng);
}

}  // namespace

std::map<std::string, Eigen::VectorXd> simulate_channels(const Track& tr, unsigned seed,
                                                         bool states) {
  std::mt19937_64 rng(seed * 6151ULL + 11);
  std::normal_distribution<double> normal(0.0, 1.0);
  const Eigen::Index n = tr.size();
  const double dt = n > 1 ? tr.t_s[1] - tr.t_s[0] : 0.1;
  auto noise = [&](double sigma) {
    Eigen::VectorXd v(n);
    for (Eigen::Index i = 0; i < n; ++i) v[i] = sigma * normal(rng);
    return v;
  };
  std::map<std::string, Eigen::VectorXd> c;
  // Strobe: 0.15 s pulses of 1.8 A every ~1.3 s, with the strobes switched off now and then.
  const Eigen::VectorXd strobe_enabled = on_off(tr.t_s, 900, 240, rng, true);
  c["cur_strb"].resize(n);
  const double period = 1.3 + 0.05 * normal(rng);
  for (Eigen::Index i = 0; i < n; ++i) {
    const double phase = std::fmod(tr.t_s[i], period);
    c["cur_strb"][i] = 0.05 + strobe_enabled[i] * (phase < 0.15 ? 1.8 : 0.0);
  }
  c["cur_strb"] += noise(0.01);
  // Fuel pump cycling, flap motor bursts, radio transmit bursts, heater thermostat.
  c["cur_tank"] = 2.5 * on_off(tr.t_s, 90, 300, rng) + noise(0.03);
  c["cur_flap"] = 8.0 * on_off(tr.t_s, 4, 900, rng) + noise(0.05);
  c["cur_com_1"] = 0.4 + 3.6 * on_off(tr.t_s, 5, 120, rng).array() + noise(0.02).array();
  c["cur_heat"] = 5.0 * on_off(tr.t_s, 30, 60, rng, true) + noise(0.05);
  // A/C fan: off, low or high, switched every few minutes.
  const Eigen::VectorXd fan_on = on_off(tr.t_s, 400, 200, rng, true);
  const Eigen::VectorXd fan_hi = on_off(tr.t_s, 300, 300, rng);
  c["cur_ac_hi"] = 3.0 * fan_on.cwiseProduct(fan_hi) + noise(0.02);
  c["cur_ac_lo"] = 1.5 * fan_on.cwiseProduct((1.0 - fan_hi.array()).matrix()) + noise(0.02);
  // INS gimbal servos follow the attitude rates.
  const Eigen::VectorXd roll_rate = central_rate(tr.roll_rad, dt, true);
  const Eigen::VectorXd pitch_rate = central_rate(tr.pitch_rad, dt, true);
  const Eigen::VectorXd yaw_rate = central_rate(tr.yaw_rad, dt, true);
  c["cur_srvo_o"] = 0.3 + 2.0 * roll_rate.cwiseAbs().array() + noise(0.02).array();
  c["cur_srvo_m"] = 0.3 + 2.0 * pitch_rate.cwiseAbs().array() + noise(0.02).array();
  c["cur_srvo_i"] = 0.3 + 2.0 * yaw_rate.cwiseAbs().array() + noise(0.02).array();
  // Bus currents: the sum of the loads; batteries charge slowly.
  Eigen::VectorXd load = Eigen::VectorXd::Constant(n, 12.0);
  for (const char* k : {"cur_strb", "cur_tank", "cur_flap", "cur_com_1", "cur_heat", "cur_ac_hi",
                        "cur_ac_lo", "cur_srvo_o", "cur_srvo_m", "cur_srvo_i"}) {
    load += c[k];
  }
  c["cur_acpwr"] = load + noise(0.1);
  c["cur_outpwr"] = 0.8 * load + noise(0.1);
  Eigen::VectorXd charge(n);
  for (Eigen::Index i = 0; i < n; ++i) charge[i] = 2.0 * std::exp(-tr.t_s[i] / 1800.0);
  c["cur_bat_1"] = charge + noise(0.02);
  c["cur_bat_2"] = 0.9 * charge + noise(0.02);
  // Voltages: nominal levels, slow drifts, sag under load.
  Eigen::VectorXd drift(n);
  double walk = 0;
  for (Eigen::Index i = 0; i < n; ++i) {
    walk += 0.002 * normal(rng);
    drift[i] = walk;
  }
  const Eigen::VectorXd sag = smooth(load, 2.0, dt) * 0.01;
  c["vol_acpwr"] = (28.0 + drift.array() - sag.array()).matrix() + noise(0.02);
  c["vol_outpwr"] = (27.8 + drift.array() - sag.array()).matrix() + noise(0.02);
  c["vol_bat_1"] = (26.5 + 0.5 * (1 - (-tr.t_s.array() / 2400.0).exp())).matrix() + noise(0.01);
  c["vol_bat_2"] = (26.4 + 0.5 * (1 - (-tr.t_s.array() / 2400.0).exp())).matrix() + noise(0.01);
  c["vol_res_p"] = Eigen::VectorXd::Constant(n, 15.0) + noise(0.005);
  c["vol_res_n"] = Eigen::VectorXd::Constant(n, -15.0) + noise(0.005);
  c["vol_back_p"] = Eigen::VectorXd::Constant(n, 5.0) + noise(0.003);
  c["vol_back_n"] = Eigen::VectorXd::Constant(n, -5.0) + noise(0.003);
  c["vol_gyro_1"] = Eigen::VectorXd::Constant(n, 26.0) + noise(0.01);
  c["vol_gyro_2"] = Eigen::VectorXd::Constant(n, 26.0) + noise(0.01);
  c["vol_acc_p"] = Eigen::VectorXd::Constant(n, 12.0) + noise(0.004);
  c["vol_acc_n"] = Eigen::VectorXd::Constant(n, -12.0) + noise(0.004);
  c["vol_block"] = (24.0 + 0.5 * drift.array()).matrix() + noise(0.01);
  c["vol_back"] = Eigen::VectorXd::Constant(n, 3.3) + noise(0.002);
  c["vol_srvo"] =
      (24.0 - 0.2 * (c["cur_srvo_o"] + c["cur_srvo_m"] + c["cur_srvo_i"]).array()).matrix() +
      noise(0.01);
  // Cabin temperature sensor (V): heats slowly while the heater runs.
  c["vol_cabt"] =
      (2.0 + 0.3 * smooth(c["cur_heat"], 600.0, dt).array() / 5.0).matrix() + noise(0.002);
  c["vol_fan"] = (12.0 * fan_on.array()).matrix() + noise(0.02);
  if (states) add_states(tr, seed, dt, &c);
  return c;
}

}  // namespace magcomp::sim
