// magcomp: sources whose rate of change another recorded source is.
#include "magcomp/core/diagnose/recorded_rates.h"

#include <cmath>
#include <limits>

#include "magcomp/core/diagnose/channel_twins.h"
#include "magcomp/core/math/correlation.h"
#include "magcomp/core/math/timeseries.h"

namespace magcomp {

namespace {

constexpr Eigen::Index kMinBlocks = 50;

// The means of x over consecutive blocks of `block` samples (NaN where fewer than half of a
// block's samples are finite).
Eigen::VectorXd block_means(const Eigen::Ref<const Eigen::VectorXd>& x, Eigen::Index block) {
  const Eigen::Index n = x.size() / block;
  Eigen::VectorXd out(n);
  for (Eigen::Index b = 0; b < n; ++b) {
    double sum = 0;
    Eigen::Index finite = 0;
    for (Eigen::Index i = b * block; i < (b + 1) * block; ++i) {
      if (std::isfinite(x[i])) {
        sum += x[i];
        ++finite;
      }
    }
    out[b] = 2 * finite >= block ? sum / static_cast<double>(finite)
                                 : std::numeric_limits<double>::quiet_NaN();
  }
  return out;
}

}  // namespace

std::vector<RecordedRate> recorded_rates(const FlightData& data,
                                         const std::vector<std::string>& sources) {
  std::vector<RecordedRate> out;
  const double dt_s = data.dt_s();
  if (!(dt_s > 0)) return out;
  const auto block = std::max<Eigen::Index>(1, std::lround(kTwinWindow_s / dt_s));
  if (data.size() / block < kMinBlocks) return out;
  std::vector<Eigen::VectorXd> level(sources.size());
  for (size_t k = 0; k < sources.size(); ++k)
    level[k] = block_means(data.column(sources[k]), block);
  for (size_t k = 0; k < sources.size(); ++k) {
    const Eigen::VectorXd rate = block_means(central_rate(data.column(sources[k]), dt_s), block);
    RecordedRate best{sources[k], "", 0.0};
    for (size_t j = 0; j < sources.size(); ++j) {
      if (j == k) continue;
      const double r = std::abs(pearson_where_finite(rate, level[j], kMinBlocks));
      if (r >= kTwinCorrelation && r > best.correlation) best = {sources[k], sources[j], r};
    }
    if (!best.rate.empty()) out.push_back(best);
  }
  return out;
}

}  // namespace magcomp
