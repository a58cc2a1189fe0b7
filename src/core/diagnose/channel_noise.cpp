// magcomp: whether a recorded channel holds anything but its own white noise.
#include "magcomp/core/diagnose/channel_noise.h"

#include <algorithm>
#include <cmath>
#include <limits>
#include <vector>

namespace magcomp {

namespace {

// The std of a white noise of x's sample-to-sample level: the median |difference| of a white
// noise of std s is 0.6745 * sqrt(2) s. NaN without two consecutive finite samples.
double white_std(const Eigen::Ref<const Eigen::VectorXd>& x) {
  std::vector<double> diff;
  diff.reserve(static_cast<size_t>(x.size()));
  for (Eigen::Index i = 1; i < x.size(); ++i)
    if (std::isfinite(x[i]) && std::isfinite(x[i - 1])) diff.push_back(std::abs(x[i] - x[i - 1]));
  if (diff.empty()) return NAN;
  std::nth_element(diff.begin(), diff.begin() + static_cast<long>(diff.size() / 2), diff.end());
  return diff[diff.size() / 2] / (0.6745 * std::sqrt(2.0));
}

// The two ratios below for a white level s (white_std(x)), so that records_noise_only reads it
// once.
double variance_ratio(const Eigen::Ref<const Eigen::VectorXd>& x, double s) {
  double sum = 0, sum2 = 0, n = 0;
  for (Eigen::Index i = 0; i < x.size(); ++i)
    if (std::isfinite(x[i])) {
      sum += x[i];
      sum2 += x[i] * x[i];
      n += 1;
    }
  if (n < 2) return NAN;
  const double var = std::max(0.0, (sum2 - sum * sum / n) / (n - 1));
  if (!(s > 0)) return var > 0 ? std::numeric_limits<double>::infinity() : NAN;
  return var / (s * s);
}

double slow_ratio(const Eigen::Ref<const Eigen::VectorXd>& x, double dt_s, double block_s,
                  double s) {
  if (!(dt_s > 0) || !(block_s > 0)) return NAN;
  const auto w = static_cast<Eigen::Index>(std::max(2.0, std::round(block_s / dt_s)));
  std::vector<double> means;
  for (Eigen::Index s = 0; s + w <= x.size(); s += w) {
    const auto b = x.segment(s, w);
    if (b.allFinite()) means.push_back(b.mean());
  }
  if (means.size() < 12) return NAN;
  double m = 0;
  for (double v : means) m += v;
  m /= static_cast<double>(means.size());
  double var_blocks = 0;
  for (double v : means) var_blocks += (v - m) * (v - m);
  var_blocks /= static_cast<double>(means.size() - 1);
  if (!std::isfinite(s)) return NAN;
  const double white = s * s / static_cast<double>(w);
  if (!(white > 0)) return var_blocks > 0 ? std::numeric_limits<double>::infinity() : NAN;
  return var_blocks / white;
}

}  // namespace

double variance_to_noise_ratio(const Eigen::Ref<const Eigen::VectorXd>& x) {
  return variance_ratio(x, white_std(x));
}

double slow_to_noise_ratio(const Eigen::Ref<const Eigen::VectorXd>& x, double dt_s,
                           double block_s) {
  return slow_ratio(x, dt_s, block_s, white_std(x));
}

bool records_noise_only(const Eigen::Ref<const Eigen::VectorXd>& x, double dt_s) {
  const double s = white_std(x);
  const double slow = slow_ratio(x, dt_s, 10.0, s), all = variance_ratio(x, s);
  return std::isfinite(slow) && slow < kNoiseOnlySlowRatio && std::isfinite(all) &&
         all < kNoiseOnlyVarianceRatio;
}

}  // namespace magcomp
