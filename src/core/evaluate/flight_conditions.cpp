// magcomp: flight-condition classification.
#include "magcomp/core/evaluate/flight_conditions.h"

#include <algorithm>
#include <array>
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

// Centred moving means and mean squares about them (the rms is its square root) over w samples
// (NaN treated as 0) of a few channels, a block of samples at a time: each channel's prefix sums
// of x (and of x²) are formed in order, as over the whole series, but kept only from the first
// window of the block on (the channels side by side, so their running sums advance together);
// each sample's figures then come from two prefix sums, with the arithmetic of one sample at a
// time (so many samples share an instruction).
class WindowStats {
 public:
  static constexpr int kChannels = 4;
  WindowStats(const std::array<const double*, kChannels>& x, Eigen::Index n, Eigen::Index w)
      : x_(x), n_(n), half_(w / 2) {}

  // Mean and mean square about it of channel c for samples [i0, i1), after prepare(i0, i1) (in
  // increasing blocks). A missing channel reads as zeros.
  void prepare(Eigen::Index i0, Eigen::Index i1) {
    extend(std::max<Eigen::Index>(0, i0 - half_), std::min(n_, i1 - 1 + half_ + 1));
  }
  void block(int c, Eigen::Index i0, Eigen::Index i1, double* mean, double* square) const {
    const Eigen::Index count = i1 - i0;
    if (!x_[static_cast<size_t>(c)]) {
      std::fill(mean, mean + count, 0.0);
      std::fill(square, square + count, 0.0);
      return;
    }
    const double* s1 = s1_[static_cast<size_t>(c)].data() - base_;  // prefix sum over x[0, j)
    const double* s2 = s2_[static_cast<size_t>(c)].data() - base_;
    auto at = [&](Eigen::Index k, Eigen::Index a, Eigen::Index b) {
      const double kk = static_cast<double>(b - a);
      const double m = (s1[b] - s1[a]) / kk;
      mean[k] = m;
      square[k] = std::max(0.0, (s2[b] - s2[a]) / kk - m * m);
    };
    // Whole windows (every sample but the first and last half window of the flight): the same
    // width, the prefix sums read in two straight runs.
    const Eigen::Index whole_from = std::max(i0, half_), whole_to = std::min(i1, n_ - half_ - 1);
    for (Eigen::Index i = i0; i < std::min(i1, whole_from); ++i) {
      at(i - i0, std::max<Eigen::Index>(0, i - half_), std::min(n_, i + half_ + 1));
    }
    if (whole_to > whole_from) {
      const double kk = static_cast<double>(2 * half_ + 1);
      const double *a1 = s1 + whole_from - half_, *b1 = s1 + whole_from + half_ + 1;
      const double *a2 = s2 + whole_from - half_, *b2 = s2 + whole_from + half_ + 1;
      double* mo = mean + (whole_from - i0);
      double* so = square + (whole_from - i0);
      for (Eigen::Index k = 0; k < whole_to - whole_from; ++k) {
        const double m = (b1[k] - a1[k]) / kk;
        mo[k] = m;
        so[k] = std::max(0.0, (b2[k] - a2[k]) / kk - m * m);
      }
    }
    for (Eigen::Index i = std::max(i0, std::max(whole_from, whole_to)); i < i1; ++i) {
      at(i - i0, std::max<Eigen::Index>(0, i - half_), std::min(n_, i + half_ + 1));
    }
  }

 private:
  // Prefix sums for indices [lo, hi] held, continuing the running sums in order.
  void extend(Eigen::Index lo, Eigen::Index hi) {
    if (held_ == 0) {
      for (int c = 0; c < kChannels; ++c) {
        s1_[static_cast<size_t>(c)].assign(1, 0.0);
        s2_[static_cast<size_t>(c)].assign(1, 0.0);
      }
      held_ = 1;
      base_ = 0;
    }
    if (lo > base_) {  // forget what no later window reaches
      const auto drop = static_cast<std::ptrdiff_t>(lo - base_);
      for (int c = 0; c < kChannels; ++c) {
        auto& a = s1_[static_cast<size_t>(c)];
        auto& b = s2_[static_cast<size_t>(c)];
        a.erase(a.begin(), a.begin() + drop);
        b.erase(b.begin(), b.begin() + drop);
      }
      held_ -= static_cast<size_t>(drop);
      base_ = lo;
    }
    const Eigen::Index from = base_ + static_cast<Eigen::Index>(held_) - 1;
    if (hi <= from) return;
    const size_t size = held_ + static_cast<size_t>(hi - from);
    double p1[kChannels], p2[kChannels], *o1[kChannels], *o2[kChannels];
    const double* x[kChannels];
    for (int c = 0; c < kChannels; ++c) {
      const auto k = static_cast<size_t>(c);
      s1_[k].resize(size);
      s2_[k].resize(size);
      p1[c] = s1_[k][held_ - 1];
      p2[c] = s2_[k][held_ - 1];
      o1[c] = s1_[k].data() + held_;
      o2[c] = s2_[k].data() + held_;
      x[c] = x_[k] ? x_[k] : kZeros;  // a missing channel: its sums stay 0 and are not read
    }
    for (Eigen::Index j = from; j < hi; ++j) {
      const Eigen::Index at = j - from;
      for (int c = 0; c < kChannels; ++c) {
        const double xj = x[c] == kZeros ? 0.0 : x[c][j];
        const double v = std::isfinite(xj) ? xj : 0.0;
        p1[c] += v;
        p2[c] += v * v;
        o1[c][at] = p1[c];
        o2[c][at] = p2[c];
      }
    }
    held_ = size;
  }

  static constexpr double kZeros[1] = {0.0};
  std::array<const double*, kChannels> x_;
  Eigen::Index n_, half_;
  std::array<std::vector<double>, kChannels> s1_, s2_;  // prefix sums for indices base_, ...
  size_t held_ = 0;
  Eigen::Index base_ = 0;
};

}  // namespace

std::vector<FlightCondition> classify_conditions(const FlightData& data, double window_s) {
  const Eigen::Index n = data.size();
  const Eigen::Index w = std::max<Eigen::Index>(3, std::llround(window_s / data.dt_s()));
  auto col = [&](const char* name) { return data.has(name) ? data.column(name).data() : nullptr; };
  WindowStats windows({col("pitch_rate"), col("roll_rate"), col("yaw_rate"), col("ins_vu")}, n, w);
  std::vector<FlightCondition> out(static_cast<size_t>(n), FlightCondition::kStraightLevel);
  constexpr Eigen::Index kBlock = 4096;
  // Means and mean squares (p, r, y: the rates' rms squared).
  std::vector<double> pm(kBlock), p(kBlock), rm(kBlock), r(kBlock), ym(kBlock), y(kBlock),
      vm(kBlock), vr(kBlock);
  // Whether an oscillation's rms sqrt(q) exceeds 1: decided on q itself away from 1, where the
  // rounded square root cannot be on the other side.
  auto above_one = [](double q) { return q > 1.0000001 || (q > 1.0 && std::sqrt(q) > 1.0); };
  for (Eigen::Index i0 = 0; i0 < n; i0 += kBlock) {
    const Eigen::Index i1 = std::min(n, i0 + kBlock);
    windows.prepare(i0, i1);
    windows.block(0, i0, i1, pm.data(), p.data());
    windows.block(1, i0, i1, rm.data(), r.data());
    windows.block(2, i0, i1, ym.data(), y.data());
    windows.block(3, i0, i1, vm.data(), vr.data());
    for (Eigen::Index k = 0; k < i1 - i0; ++k) {
      FlightCondition c = FlightCondition::kStraightLevel;
      if (std::abs(ym[k]) > 1.5) {
        c = FlightCondition::kTurn;
      } else if (std::abs(vm[k]) > 2.0) {
        c = FlightCondition::kClimbDescent;
      } else if (above_one(p[k]) || above_one(r[k]) || above_one(y[k])) {
        const double pr = std::sqrt(p[k]), rr = std::sqrt(r[k]), yr = std::sqrt(y[k]);
        c = (pr >= rr && pr >= yr) ? FlightCondition::kPitchManeuver
            : (rr >= yr)           ? FlightCondition::kRollManeuver
                                   : FlightCondition::kYawManeuver;
      }
      out[static_cast<size_t>(i0 + k)] = c;
    }
    // The rows behind the window are done with: a file read in place need not stay resident.
    if ((i1 & 0xffff) == 0) data.drop_mapped_pages(i1 - w);
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
  for (Eigen::Index i = 0; i < data.size(); ++i)
    out[static_cast<size_t>(i)] = heading_sector(yaw[i]);
  return out;
}

}  // namespace magcomp
