// magcomp: flight-condition classification.
#include "magcomp/core/flight_conditions.h"

#include <algorithm>
#include <cmath>
#include <vector>

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

// Centred moving mean and rms-about-mean over w samples (NaN treated as 0), one sample at a time
// in order: the prefix sums are kept only over the window, with the same
// arithmetic as whole-series prefix sums; the ring holds at least w + 2.
class WindowStats {
 public:
  WindowStats(const double* x, Eigen::Index n, Eigen::Index w) : x_(x), n_(n), w_(w) {
    size_t size = 1;
    while (size < static_cast<size_t>(w + 2)) size *= 2;  // a power of two: the slot is a mask
    ring_.resize(size);
    mask_ = size - 1;
    ring_[0] = {0.0, 0.0};
  }
  // Mean and rms about it of the window centred on sample i (i = 0, 1, ... in order).
  void at(Eigen::Index i, double* mean, double* rms) {
    if (!x_) {  // a missing channel reads as zeros
      *mean = 0.0;
      *rms = 0.0;
      return;
    }
    const Eigen::Index a = std::max<Eigen::Index>(0, i - w_ / 2), b = std::min(n_, i + w_ / 2 + 1);
    while (filled_ < b) {  // prefix sums up to index b
      const double v = std::isfinite(x_[filled_]) ? x_[filled_] : 0.0;
      const Sums& p = ring_[slot(filled_)];
      ring_[slot(filled_ + 1)] = {p.s1 + v, p.s2 + v * v};
      ++filled_;
    }
    const double k = static_cast<double>(b - a);
    const Sums& sb = ring_[slot(b)];
    const Sums& sa = ring_[slot(a)];
    const double m = (sb.s1 - sa.s1) / k;
    *mean = m;
    *rms = std::sqrt(std::max(0.0, (sb.s2 - sa.s2) / k - m * m));
  }

 private:
  struct Sums {
    double s1, s2;
  };
  size_t slot(Eigen::Index i) const { return static_cast<size_t>(i) & mask_; }
  const double* x_;
  Eigen::Index n_, w_, filled_ = 0;
  std::vector<Sums> ring_;
  size_t mask_ = 0;
};

}  // namespace

std::vector<FlightCondition> classify_conditions(const FlightData& data, double window_s) {
  const Eigen::Index n = data.size();
  const Eigen::Index w = std::max<Eigen::Index>(3, std::llround(window_s / data.dt_s()));
  auto col = [&](const char* name) {
    return data.has(name) ? data.column(name).data() : nullptr;
  };
  WindowStats pitch(col("pitch_rate"), n, w), roll(col("roll_rate"), n, w),
      yaw(col("yaw_rate"), n, w), vertical(col("ins_vu"), n, w);
  std::vector<FlightCondition> out(static_cast<size_t>(n), FlightCondition::kStraightLevel);
  for (Eigen::Index i = 0; i < n; ++i) {
    double pm, p, rm, r, ym, y, vm, vr;
    pitch.at(i, &pm, &p);
    roll.at(i, &rm, &r);
    yaw.at(i, &ym, &y);
    vertical.at(i, &vm, &vr);
    FlightCondition c = FlightCondition::kStraightLevel;
    if (std::abs(ym) > 1.5) {
      c = FlightCondition::kTurn;
    } else if (std::abs(vm) > 2.0) {
      c = FlightCondition::kClimbDescent;
    } else if (std::max({p, r, y}) > 1.0) {
      c = (p >= r && p >= y) ? FlightCondition::kPitchManeuver
          : (r >= y)         ? FlightCondition::kRollManeuver
                             : FlightCondition::kYawManeuver;
    }
    out[static_cast<size_t>(i)] = c;
    // The rows behind the window are done with: a file read in place need not stay resident.
    if ((i & 0xffff) == 0xffff) data.drop_mapped_pages(i - w);
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
  const FlightData::Column yaw = data.column("ins_yaw");
  for (Eigen::Index i = 0; i < data.size(); ++i) out[static_cast<size_t>(i)] = heading_sector(yaw[i]);
  return out;
}

}  // namespace magcomp
