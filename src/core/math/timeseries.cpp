// magcomp: time-series helpers.
#include "magcomp/core/math/timeseries.h"

#include <algorithm>
#include <cmath>
#include <limits>

namespace magcomp {

namespace {
// True when a shift (samples) is a whole number of samples: no interpolation.
bool whole_samples(double shift) { return std::abs(shift - std::round(shift)) < 1e-6; }

// Cubic (Catmull-Rom) value between samples i and i + 1 at fraction f in [0, 1).
double cubic_between(const Eigen::Ref<const Eigen::VectorXd>& x, Eigen::Index i, double f) {
  const Eigen::Index n = x.size();
  auto at = [&](Eigen::Index k) { return x[std::clamp<Eigen::Index>(k, 0, n - 1)]; };
  const double p0 = at(i - 1), p1 = at(i), p2 = at(i + 1), p3 = at(i + 2);
  return p1 +
         0.5 * f * (p2 - p0 + f * (2 * p0 - 5 * p1 + 4 * p2 - p3 + f * (3 * (p1 - p2) + p3 - p0)));
}
}  // namespace

double cubic_at(const Eigen::Ref<const Eigen::VectorXd>& x, double u) {
  const Eigen::Index i = static_cast<Eigen::Index>(std::floor(u));
  return cubic_between(x, i, u - static_cast<double>(i));
}

Eigen::VectorXd shift_samples(const Eigen::Ref<const Eigen::VectorXd>& x, double shift,
                              bool hold_ends) {
  const Eigen::Index n = x.size();
  Eigen::VectorXd y(n);
  const double whole = std::round(shift);
  const bool exact = whole_samples(shift);  // whole samples: no interpolation
  // y[i] = x(i + offset + f): the whole offset and the fraction are the same for every sample,
  // so a sample's value does not depend on its index (a slice of rows gives the same numbers).
  const double base = std::floor(exact ? -whole : -shift);
  const Eigen::Index offset = static_cast<Eigen::Index>(base);
  const double f = exact ? 0.0 : -shift - base;
  for (Eigen::Index i = 0; i < n; ++i) {
    const Eigen::Index k = i + offset;  // the sample at or before x(i - shift)
    if (!hold_ends && (k < 0 || k > n - 1 || (k == n - 1 && f > 0.0))) {
      y[i] = std::numeric_limits<double>::quiet_NaN();
    } else if (exact) {
      y[i] = x[std::clamp<Eigen::Index>(k, 0, n - 1)];
    } else {
      y[i] = cubic_between(x, k, f);
    }
  }
  return y;
}

int lag_round_trip_reach(double lag_samples) {
  return whole_samples(lag_samples) || !std::isfinite(lag_samples) ? 0 : 3;
}

int lag_round_trip_slice_margin(double lag_samples) {
  if (lag_round_trip_reach(lag_samples) == 0) return 0;
  return static_cast<int>(std::ceil(std::abs(lag_samples))) + 3;
}

void lag_round_trip(Eigen::Ref<Eigen::MatrixXd> a, double lag_samples) {
  if (lag_round_trip_reach(lag_samples) == 0) return;
  for (Eigen::Index c = 0; c < a.cols(); ++c) {
    a.col(c) = shift_samples(shift_samples(a.col(c), lag_samples, true), -lag_samples, true);
  }
}

Eigen::VectorXd central_rate(const Eigen::Ref<const Eigen::VectorXd>& x, double dt_s,
                             bool wrap_angle) {
  const Eigen::Index n = x.size();
  Eigen::VectorXd d(n);
  for (Eigen::Index i = 0; i < n; ++i) {
    const Eigen::Index a = std::max<Eigen::Index>(i - 1, 0),
                       b = std::min<Eigen::Index>(i + 1, n - 1);
    const double step = wrap_angle ? std::remainder(x[b] - x[a], 2 * M_PI) : x[b] - x[a];
    d[i] = step / (static_cast<double>(std::max<Eigen::Index>(b - a, 1)) * dt_s);
  }
  return d;
}

Eigen::VectorXd moving_average(const Eigen::Ref<const Eigen::VectorXd>& x, Eigen::Index half) {
  const Eigen::Index n = x.size();
  half = std::max<Eigen::Index>(0, half);
  Eigen::VectorXd sum = Eigen::VectorXd::Zero(n + 1), count = Eigen::VectorXd::Zero(n + 1);
  for (Eigen::Index i = 0; i < n; ++i) {
    const bool finite = std::isfinite(x[i]);
    sum[i + 1] = sum[i] + (finite ? x[i] : 0.0);
    count[i + 1] = count[i] + (finite ? 1.0 : 0.0);
  }
  Eigen::VectorXd out(n);
  for (Eigen::Index i = 0; i < n; ++i) {
    const Eigen::Index lo = std::max<Eigen::Index>(0, i - half),
                       hi = std::min<Eigen::Index>(n, i + half + 1);
    const double c = count[hi] - count[lo];
    out[i] = c > 0 ? (sum[hi] - sum[lo]) / c : std::numeric_limits<double>::quiet_NaN();
  }
  return out;
}

}  // namespace magcomp
