// magcomp simulator: flight-plan kinematics.
#include "magcomp/core/sim/trajectory.h"

#include <cmath>
#include <random>
#include <vector>

#include "magcomp/core/math/constants.h"

namespace magcomp::sim {
namespace {

constexpr double kRampS = 2.0;  // roll-in / roll-out of a turn

// One leg of the expanded plan.
struct Leg {
  double duration_s = 0;
  double line = 0;
  double heading_rad = NAN;  // straight legs: heading to hold (NaN: keep current)
  double turn_rad = 0;       // turn legs: signed heading change (+ right)
  double climb_mps = 0;
  bool maneuvers = false;  // calibration box leg: pitch, roll, yaw thirds
};

double wrap(double a) { return std::atan2(std::sin(a), std::cos(a)); }

class Planner {
 public:
  explicit Planner(const Scenario& s)
      : s_(s), rate_(kStandardGravity_mps2 * std::tan(s.turn_bank_deg * kDegToRad) / s.speed_mps) {}

  std::vector<Leg> expand() {
    heading_ = s_.segments.front().heading_deg * kDegToRad;
    altitude_ = s_.start_altitude_m;
    const double transit_line = std::floor(s_.flight) + 0.99;
    for (const Segment& g : s_.segments) {
      if (g.altitude_m > 0 && std::abs(g.altitude_m - altitude_) > 1.0) {
        const double dh = g.altitude_m - altitude_;
        Leg c;
        c.duration_s = std::abs(dh) / s_.climb_rate_mps;
        c.line = transit_line;
        c.climb_mps = dh > 0 ? s_.climb_rate_mps : -s_.climb_rate_mps;
        legs_.push_back(c);
        altitude_ = g.altitude_m;
      }
      const double h = g.heading_deg * kDegToRad;
      if (g.type == "box" || g.type == "cloverleaf") {
        const double order_box[4] = {0, 90, 180, 270};
        const double order_clover[4] = {0, 180, 90, 270};
        for (int k = 0; k < 4; ++k) {
          const double target = h + (g.type == "box" ? order_box[k] : order_clover[k]) * kDegToRad;
          turn_to(target, transit_line, g.type == "cloverleaf");
          straight(g.duration_s, g.line, true);
        }
      } else if (g.type == "line") {
        turn_to(h, transit_line, false);
        straight(g.duration_s, g.line, false);
      } else if (g.type == "grid") {
        for (int j = 0; j < g.lines; ++j) {
          turn_to(h + (j % 2) * M_PI, transit_line, false);
          straight(g.duration_s, g.line + 0.01 * j, false);
        }
      } else if (g.type == "figure8") {
        const double circle_s = 2 * M_PI / rate_ + kRampS;
        const int circles = std::max(1, static_cast<int>(g.duration_s / circle_s));
        for (int c = 0; c < circles; ++c) {
          Leg l;
          l.turn_rad = (c % 2 ? -1 : 1) * 2 * M_PI;
          l.duration_s = circle_s;
          l.line = g.line;
          legs_.push_back(l);
        }
      }
    }
    return legs_;
  }

 private:
  void turn_to(double target, double line, bool always_right) {
    double d = wrap(target - heading_);
    if (always_right && d < 0) d += 2 * M_PI;
    if (std::abs(d) > 1e-6) {
      Leg l;
      l.turn_rad = d;
      l.duration_s = std::abs(d) / rate_ + kRampS;
      l.line = line;
      legs_.push_back(l);
    }
    heading_ = target;
  }
  void straight(double duration, double line, bool maneuvers) {
    Leg l;
    l.duration_s = duration;
    l.line = line;
    l.heading_rad = heading_;
    l.maneuvers = maneuvers;
    legs_.push_back(l);
  }

  const Scenario& s_;
  double rate_;
  double heading_ = 0, altitude_ = 0;
  std::vector<Leg> legs_;
};

// Smooth envelope on [0, 1]: 0 at the ends, 1 in the middle (tapered cosine).
double envelope(double u) {
  const double taper = 0.15;
  if (u < 0 || u > 1) return 0;
  if (u < taper) return 0.5 * (1 - std::cos(M_PI * u / taper));
  if (u > 1 - taper) return 0.5 * (1 - std::cos(M_PI * (1 - u) / taper));
  return 1;
}

}  // namespace

namespace {

// A calibration leg at time tau (s) into it, of length leg_s (s): pitch +-5 deg, then roll
// +-10 deg, then yaw +-5 deg, each a third, added to the attitude (rad). Returns the maneuver
// code (1 pitch, 2 roll, 3 yaw).
int calibration_maneuver(double tau, double leg_s, double* pitch, double* roll,
                         double* yaw_offset) {
  const double third = leg_s / 3;
  const int part = std::min(2, static_cast<int>(tau / third));
  const double u = (tau - part * third) / third;
  const double e = envelope(u);
  const double local = tau - part * third;
  if (part == 0) *pitch += 5 * kDegToRad * e * std::sin(2 * M_PI * local / 6.0);
  if (part == 1) *roll += 10 * kDegToRad * e * std::sin(2 * M_PI * local / 8.0);
  if (part == 2) *yaw_offset = 5 * kDegToRad * e * std::sin(2 * M_PI * local / 7.0);
  return 1 + part;
}

// A track of n samples, every series allocated.
Track sized_track(Eigen::Index n) {
  Track tr;
  for (Eigen::VectorXd* v : {&tr.t_s, &tr.line, &tr.yaw_rad, &tr.pitch_rad, &tr.roll_rad,
                             &tr.north_m, &tr.east_m, &tr.alt_m, &tr.vn_mps, &tr.ve_mps, &tr.vu_mps,
                             &tr.speed_mps, &tr.lat_deg, &tr.lon_deg, &tr.maneuver}) {
    v->resize(n);
  }
  return tr;
}

}  // namespace

Track fly(const Scenario& s) {
  const std::vector<Leg> legs = Planner(s).expand();
  const double dt = 1.0 / s.sample_rate_hz;
  double total = 0;
  std::vector<Eigen::Index> leg_samples;
  for (const Leg& l : legs) {
    const Eigen::Index n = std::max<Eigen::Index>(1, std::llround(l.duration_s / dt));
    leg_samples.push_back(n);
    total += static_cast<double>(n);
  }
  Track tr = sized_track(static_cast<Eigen::Index>(total));
  std::mt19937_64 rng(s.seed * 7919ULL + 17);
  std::normal_distribution<double> normal(0.0, 1.0);
  // Turbulence: first-order Gauss-Markov processes on the attitude, correlation 1.5 s.
  const double corr = std::exp(-dt / 1.5);
  const double drive = std::sqrt(1 - corr * corr) * s.turbulence_deg * kDegToRad;
  double tb_roll = 0, tb_pitch = 0, tb_yaw = 0, tb_speed = 0;
  double heading = s.segments.front().heading_deg * kDegToRad;
  double north = 0, east = 0, alt = s.start_altitude_m;
  Eigen::Index i = 0;
  for (size_t k = 0; k < legs.size(); ++k) {
    const Leg& l = legs[k];
    const Eigen::Index m = leg_samples[k];
    const double leg_s = static_cast<double>(m) * dt;
    // Turns: bank ramps in and out; the hold time makes the heading change come out right.
    const double rate = l.turn_rad / std::max(leg_s - kRampS, dt);
    for (Eigen::Index j = 0; j < m; ++j, ++i) {
      const double tau = static_cast<double>(j) * dt;
      tb_roll = corr * tb_roll + drive * normal(rng);
      tb_pitch = corr * tb_pitch + drive * normal(rng);
      tb_yaw = corr * tb_yaw + 0.5 * drive * normal(rng);
      tb_speed = corr * tb_speed + std::sqrt(1 - corr * corr) * 0.5 * normal(rng);
      double heading_rate = 0, roll = 0, pitch = 0, yaw_offset = 0;
      int maneuver = 0;
      if (l.turn_rad != 0) {
        const double ramp = std::min({tau / kRampS, (leg_s - tau) / kRampS, 1.0});
        heading_rate = rate * std::max(ramp, 0.0);  // trapezoid: its integral is turn_rad
        roll = std::atan(heading_rate * s.speed_mps / kStandardGravity_mps2);
      } else if (!std::isnan(l.heading_rad)) {
        heading += 0.05 * wrap(l.heading_rad - heading) * dt;  // autopilot holds the heading
      }
      if (l.maneuvers) maneuver = calibration_maneuver(tau, leg_s, &pitch, &roll, &yaw_offset);
      const double v = s.speed_mps + tb_speed;
      const double climb_angle = std::asin(std::clamp(l.climb_mps / v, -0.3, 0.3));
      heading = wrap(heading + heading_rate * dt);
      const double yaw = wrap(heading + yaw_offset + tb_yaw);
      pitch += climb_angle + tb_pitch;
      roll += tb_roll;
      const double vh = v * std::cos(climb_angle);
      const double vn = vh * std::cos(heading), ve = vh * std::sin(heading);
      // Vertical speed: the climb, plus the pitch maneuver's altitude oscillation.
      const double vu = l.climb_mps + v * std::sin(pitch - climb_angle - tb_pitch) * 0.5;
      north += vn * dt;
      east += ve * dt;
      alt += vu * dt;
      tr.t_s[i] = static_cast<double>(i) * dt;
      tr.line[i] = l.line;
      tr.yaw_rad[i] = yaw;
      tr.pitch_rad[i] = pitch;
      tr.roll_rad[i] = roll;
      tr.north_m[i] = north;
      tr.east_m[i] = east;
      tr.alt_m[i] = alt;
      tr.vn_mps[i] = vn;
      tr.ve_mps[i] = ve;
      tr.vu_mps[i] = vu;
      tr.speed_mps[i] = v;
      tr.lat_deg[i] = s.origin_lat_deg + north / kMeanEarthRadius_m / kDegToRad;
      tr.lon_deg[i] =
          s.origin_lon_deg +
          east / (kMeanEarthRadius_m * std::cos(s.origin_lat_deg * kDegToRad)) / kDegToRad;
      tr.maneuver[i] = maneuver;
    }
  }
  return tr;
}

}  // namespace magcomp::sim
