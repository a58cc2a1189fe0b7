// magcomp: time-series helpers.
#include "magcomp/core/timeseries.h"

#include <algorithm>
#include <cmath>
#include <limits>

namespace magcomp {

double cubic_at(const Eigen::VectorXd& x, double u) {
  const Eigen::Index n = x.size();
  const Eigen::Index i = static_cast<Eigen::Index>(std::floor(u));
  const double f = u - static_cast<double>(i);
  auto at = [&](Eigen::Index k) { return x[std::clamp<Eigen::Index>(k, 0, n - 1)]; };
  const double p0 = at(i - 1), p1 = at(i), p2 = at(i + 1), p3 = at(i + 2);
  return p1 +
         0.5 * f * (p2 - p0 + f * (2 * p0 - 5 * p1 + 4 * p2 - p3 + f * (3 * (p1 - p2) + p3 - p0)));
}

Eigen::VectorXd shift_samples(const Eigen::VectorXd& x, double shift, bool hold_ends) {
  const Eigen::Index n = x.size();
  Eigen::VectorXd y(n);
  const double whole = std::round(shift);
  const bool exact = std::abs(shift - whole) < 1e-6;  // whole samples: no interpolation
  for (Eigen::Index i = 0; i < n; ++i) {
    const double u = static_cast<double>(i) - (exact ? whole : shift);
    if (!hold_ends && (u < 0.0 || u > static_cast<double>(n - 1))) {
      y[i] = std::numeric_limits<double>::quiet_NaN();
    } else if (exact) {
      y[i] = x[std::clamp<Eigen::Index>(static_cast<Eigen::Index>(u), 0, n - 1)];
    } else {
      y[i] = cubic_at(x, u);
    }
  }
  return y;
}

}  // namespace magcomp
