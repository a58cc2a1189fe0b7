// magcomp: flight-condition classification.
#include "magcomp/core/flight_conditions.h"

#include <cmath>

namespace magcomp {

const char* condition_name(FlightCondition c) {
  switch (c) {
    case FlightCondition::kStraightLevel:
      return "straight_level";
    case FlightCondition::kTurn:
      return "turn";
    case FlightCondition::kClimbDescent:
      return "climb_descent";
    case FlightCondition::kPitchManeuver:
      return "maneuver_pitch";
    case FlightCondition::kRollManeuver:
      return "maneuver_roll";
    case FlightCondition::kYawManeuver:
      return "maneuver_yaw";
  }
  return "unknown";
}

const char* sector_name(int s) {
  static const char* kNames[8] = {"N", "NE", "E", "SE", "S", "SW", "W", "NW"};
  return s >= 0 && s < 8 ? kNames[s] : "unknown";
}

namespace {

// Centred moving mean and rms-about-mean over w samples (NaN treated as 0).
void window_stats(const Eigen::VectorXd& x, Eigen::Index w, Eigen::VectorXd* mean,
                  Eigen::VectorXd* rms) {
  const Eigen::Index n = x.size();
  Eigen::VectorXd s1 = Eigen::VectorXd::Zero(n + 1), s2 = Eigen::VectorXd::Zero(n + 1);
  for (Eigen::Index i = 0; i < n; ++i) {
    const double v = std::isfinite(x[i]) ? x[i] : 0.0;
    s1[i + 1] = s1[i] + v;
    s2[i + 1] = s2[i] + v * v;
  }
  mean->resize(n);
  rms->resize(n);
  for (Eigen::Index i = 0; i < n; ++i) {
    const Eigen::Index a = std::max<Eigen::Index>(0, i - w / 2), b = std::min(n, i + w / 2 + 1);
    const double k = static_cast<double>(b - a);
    const double m = (s1[b] - s1[a]) / k;
    (*mean)[i] = m;
    (*rms)[i] = std::sqrt(std::max(0.0, (s2[b] - s2[a]) / k - m * m));
  }
}

}  // namespace

std::vector<FlightCondition> classify_conditions(const FlightData& data, double window_s) {
  const Eigen::Index n = data.size();
  const Eigen::Index w = std::max<Eigen::Index>(3, std::llround(window_s / data.dt_s()));
  auto col = [&](const char* name) {
    return data.has(name) ? data.column(name) : Eigen::VectorXd(Eigen::VectorXd::Zero(n));
  };
  Eigen::VectorXd pm, pr, rm, rr, ym, yr, vm, vr;
  window_stats(col("pitch_rate"), w, &pm, &pr);
  window_stats(col("roll_rate"), w, &rm, &rr);
  window_stats(col("yaw_rate"), w, &ym, &yr);
  window_stats(col("ins_vu"), w, &vm, &vr);
  std::vector<FlightCondition> out(static_cast<size_t>(n), FlightCondition::kStraightLevel);
  for (Eigen::Index i = 0; i < n; ++i) {
    FlightCondition c = FlightCondition::kStraightLevel;
    if (std::abs(ym[i]) > 1.5) {
      c = FlightCondition::kTurn;
    } else if (std::abs(vm[i]) > 2.0) {
      c = FlightCondition::kClimbDescent;
    } else {
      const double p = pr[i], r = rr[i], y = yr[i];
      if (std::max({p, r, y}) > 1.0) {
        c = (p >= r && p >= y) ? FlightCondition::kPitchManeuver
            : (r >= y)         ? FlightCondition::kRollManeuver
                               : FlightCondition::kYawManeuver;
      }
    }
    out[static_cast<size_t>(i)] = c;
  }
  return out;
}

bool ManeuverDetector::update(double t, double p, double r, double y) {
  if (!samples_.empty() && t < samples_.back().t) samples_.clear();  // time went back: start over
  samples_.push_back({t, p, r, y});
  size_t first = 0;
  while (first < samples_.size() && samples_[first].t < t - window_s_) ++first;
  if (first > 0) samples_.erase(samples_.begin(), samples_.begin() + static_cast<long>(first));
  if (samples_.back().t - samples_.front().t < 0.5 * window_s_) return false;
  double s[3] = {0, 0, 0}, s2[3] = {0, 0, 0};
  for (const Rates& x : samples_) {
    const double v[3] = {x.p, x.r, x.y};
    for (int k = 0; k < 3; ++k) {
      s[k] += v[k];
      s2[k] += v[k] * v[k];
    }
  }
  const double n = static_cast<double>(samples_.size());
  double osc = 0;
  for (int k = 0; k < 3; ++k)
    osc = std::max(osc, std::sqrt(std::max(0.0, s2[k] / n - std::pow(s[k] / n, 2))));
  return osc > threshold_dps_ && std::abs(s[2] / n) < 1.5;
}

std::vector<int> heading_sectors(const FlightData& data) {
  std::vector<int> out(static_cast<size_t>(data.size()), -1);
  if (!data.has("ins_yaw")) return out;
  const Eigen::VectorXd& yaw = data.column("ins_yaw");
  for (Eigen::Index i = 0; i < data.size(); ++i) {
    if (!std::isfinite(yaw[i])) continue;
    const double h = std::fmod(std::fmod(yaw[i], 360.0) + 360.0 + 22.5, 360.0);
    out[static_cast<size_t>(i)] = static_cast<int>(h / 45.0) % 8;
  }
  return out;
}

}  // namespace magcomp
