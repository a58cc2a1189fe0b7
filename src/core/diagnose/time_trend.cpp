// magcomp: channels that follow a smooth curve of the flight's time (time_trend.h).
#include "magcomp/core/diagnose/time_trend.h"

#include <Eigen/QR>
#include <algorithm>
#include <cmath>

namespace magcomp {

double time_trend_share(const Eigen::Ref<const Eigen::VectorXd>& x, double dt_s, double block_s,
                        int degree) {
  if (!(dt_s > 0) || !(block_s > 0) || degree < 0) return NAN;
  const auto per_block = std::max<Eigen::Index>(1, std::llround(block_s / dt_s));
  std::vector<double> t, m;
  for (Eigen::Index start = 0; start + per_block <= x.size(); start += per_block) {
    const auto b = x.segment(start, per_block);
    if (!b.allFinite()) continue;
    t.push_back((static_cast<double>(start) + 0.5 * static_cast<double>(per_block)) * dt_s);
    m.push_back(b.mean());
  }
  const auto n = static_cast<Eigen::Index>(m.size());
  if (n < 20 || n <= degree + 1) return NAN;
  const Eigen::Map<const Eigen::VectorXd> y(m.data(), n);
  const double mean = y.mean();
  const double total = (y.array() - mean).square().sum();
  if (!(total > 0)) return NAN;
  // Time mapped onto [-1, 1]: its powers stay well conditioned.
  const double t0 = t.front(), t1 = t.back();
  Eigen::MatrixXd a(n, degree + 1);
  for (Eigen::Index i = 0; i < n; ++i) {
    const double u = t1 > t0 ? 2 * (t[static_cast<size_t>(i)] - t0) / (t1 - t0) - 1 : 0.0;
    double p = 1;
    for (int k = 0; k <= degree; ++k, p *= u) a(i, k) = p;
  }
  const Eigen::VectorXd residual = y - a * a.colPivHouseholderQr().solve(y);
  return std::max(0.0, 1.0 - residual.squaredNorm() / total);
}

std::vector<TimeTrend> time_trend(const std::string& channel,
                                  const std::vector<const FlightData*>& flights) {
  double least = INFINITY;
  for (const FlightData* f : flights) {
    if (!f->has(channel)) return {};
    const double share = time_trend_share(Eigen::VectorXd(f->column(channel)), f->dt_s());
    if (!(share >= kTimeTrendShare)) return {};
    least = std::min(least, share);
  }
  if (!std::isfinite(least)) return {};
  return {{channel, least}};
}

}  // namespace magcomp
