// magcomp: a step's threshold pinned on the selection lines where the calibration rows cannot
// tell the thresholds apart (see search.h, Search::threshold_on_selection).
#include <Eigen/Core>
#include <algorithm>
#include <cmath>
#include <limits>
#include <vector>

#include "magcomp/core/fit/parameter_fit.h"
#include "magcomp/core/model/terms_expr.h"
#include "search.h"

namespace magcomp::diagnose_search {

double Search::threshold_on_selection(const ExprTerm& expr, const std::vector<double>& values,
                                      double threshold, double selection_nT, bool slow_ok,
                                      long* fits) const {
  if (values.size() < 2 || yf.size() == 0) return threshold;
  const auto columns_at = [&](double x) {
    return columns_of(*make_term(expr.with_parameters({x})));
  };
  const auto rss_at = [&](double x) {
    ++*fits;
    return fit_rss(columns_at(x));
  };
  const double best_rss = rss_at(threshold);
  if (!std::isfinite(best_rss)) return threshold;
  const double tolerance = kThresholdTieChi2 * best_rss / static_cast<double>(yf.size());
  // The signal's values on the calibration runs: the fit rows' column changes only where the
  // threshold crosses one of them.
  const Eigen::VectorXd product = signal_sources_product(expr.signal(), data);
  std::vector<double> fitted;
  for (const auto& [first, last] : runs)
    for (Eigen::Index i = first; i <= last; ++i)
      if (std::isfinite(product[i])) fitted.push_back(product[i]);
  std::sort(fitted.begin(), fitted.end());
  fitted.erase(std::unique(fitted.begin(), fitted.end()), fitted.end());
  if (fitted.size() < 2) return threshold;
  // The pieces [fitted[k], fitted[k + 1]) next to the threshold's, while their residual stays
  // within the tolerance: lo and hi bound the thresholds the calibration rows cannot refuse.
  const auto at_or_below = std::upper_bound(fitted.begin(), fitted.end(), threshold);
  const auto piece = static_cast<std::ptrdiff_t>(at_or_below - fitted.begin()) - 1;
  const auto n_fitted = static_cast<std::ptrdiff_t>(fitted.size());
  double lo = piece >= 0 ? fitted[static_cast<size_t>(piece)] : values.front();
  double hi = piece + 1 < n_fitted ? fitted[static_cast<size_t>(piece + 1)] : values.back();
  for (std::ptrdiff_t k = piece - 1, steps = 0; k >= 0 && steps < kThresholdTiePieces;
       --k, ++steps) {
    const double mid = 0.5 * (fitted[static_cast<size_t>(k)] + fitted[static_cast<size_t>(k + 1)]);
    if (!(rss_at(mid) <= best_rss + tolerance)) break;
    lo = fitted[static_cast<size_t>(k)];
  }
  for (std::ptrdiff_t k = piece + 1, steps = 0; k + 1 < n_fitted && steps < kThresholdTiePieces;
       ++k, ++steps) {
    const double mid = 0.5 * (fitted[static_cast<size_t>(k)] + fitted[static_cast<size_t>(k + 1)]);
    if (!(rss_at(mid) <= best_rss + tolerance)) break;
    hi = fitted[static_cast<size_t>(k + 1)];
  }
  // The thresholds that split the flight's samples differently within [lo, hi): the middles of
  // the gaps between its values there.
  std::vector<double> trial;
  for (size_t j = 0; j + 1 < values.size(); ++j) {
    if (!(values[j + 1] > values[j])) continue;
    const double mid = 0.5 * (values[j] + values[j + 1]);
    if (mid >= lo && mid < hi) trial.push_back(mid);
  }
  if (trial.size() < 2) return threshold;
  // Coarse to fine over the trials (the selection error of a switched load grows with every
  // sample on the wrong side, with valleys no wider than the samples between them).
  const auto selection_at = [&](size_t j) {
    ++*fits;
    const Scored s = score(columns_at(trial[j]), slow_ok);
    return s.ok && std::isfinite(s.sel) ? s.sel : std::numeric_limits<double>::infinity();
  };
  size_t first = 0, last = trial.size() - 1, best_j = 0;
  double best_sel = std::numeric_limits<double>::infinity();
  while (true) {
    const size_t count = last - first + 1;
    const size_t probes = std::min<size_t>(count, kThresholdProbes);
    std::vector<size_t> at;
    for (size_t p = 0; p < probes; ++p)
      at.push_back(first + (probes > 1 ? p * (count - 1) / (probes - 1) : 0));
    at.erase(std::unique(at.begin(), at.end()), at.end());
    size_t k_best = 0;
    double round_best = std::numeric_limits<double>::infinity();
    for (size_t k = 0; k < at.size(); ++k) {
      const double f = selection_at(at[k]);
      if (f < round_best) {
        round_best = f;
        k_best = k;
      }
    }
    if (round_best < best_sel) {
      best_sel = round_best;
      best_j = at[k_best];
    }
    if (count <= kThresholdProbes) break;
    first = at[k_best > 0 ? k_best - 1 : 0];
    last = at[std::min(k_best + 1, at.size() - 1)];
  }
  if (!(best_sel < selection_nT)) return threshold;
  return written_threshold(values, trial[best_j]);
}

}  // namespace magcomp::diagnose_search
