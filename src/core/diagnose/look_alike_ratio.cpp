// magcomp: what would tell a look-alike from the kept term: the recorded channel that the ratio
// of their two channels follows (LoopRound::look_alike_ratios), such as a lateral acceleration
// over a yaw rate following the airspeed.
#include <algorithm>
#include <cmath>
#include <set>

#include "loop_steps.h"
#include "magcomp/core/io/channel_kinds.h"
#include "magcomp/core/math/correlation.h"

namespace magcomp::loop_steps {

namespace {

// A sample of the ratio: its flight, its row and kept / alike there.
struct RatioSample {
  size_t flight;
  Eigen::Index row;
  double ratio;
};

// The product of a flight's columns `names`, sample by sample (a term's channels together).
Eigen::VectorXd product_of(const FlightData& d, const std::set<std::string>& names) {
  Eigen::VectorXd p = Eigen::VectorXd::Ones(d.size());
  for (const std::string& x : names) p.array() *= d.column(x).array();
  return p;
}

// Channel names joined as a product writes them ("a*b").
std::string joined(const std::set<std::string>& names) {
  std::string out;
  for (const std::string& x : names) out += (out.empty() ? "" : "*") + x;
  return out;
}

// The channel (neither among `excluded` nor `truth`) that the ratio of the product of `kept` to
// the product of `alike` follows most closely, as look_alike_ratio says.
std::optional<LookAlikeRatio> ratio_of_products(const std::vector<const FlightData*>& flights,
                                                const std::set<std::string>& kept,
                                                const std::set<std::string>& alike,
                                                const std::set<std::string>& excluded,
                                                const std::string& truth) {
  // The ratio where the look-alike's channel is large: |alike| at least half its 95th percentile
  // on each flight (a rate crosses zero between turns, where the ratio is noise over noise).
  std::vector<RatioSample> samples;
  for (size_t f = 0; f < flights.size(); ++f) {
    const FlightData& d = *flights[f];
    for (const auto* names : {&kept, &alike})
      for (const std::string& x : *names)
        if (!d.has(x)) return std::nullopt;
    const Eigen::VectorXd k = product_of(d, kept), a = product_of(d, alike);
    std::vector<double> magnitude;
    for (Eigen::Index i = 0; i < a.size(); ++i)
      if (std::isfinite(a[i]) && std::isfinite(k[i])) magnitude.push_back(std::fabs(a[i]));
    if (magnitude.empty()) continue;
    const size_t q = std::min(magnitude.size() - 1, magnitude.size() * 95 / 100);
    std::nth_element(magnitude.begin(), magnitude.begin() + static_cast<std::ptrdiff_t>(q),
                     magnitude.end());
    const double threshold = 0.5 * magnitude[q];
    if (!(threshold > 0)) continue;
    for (Eigen::Index i = 0; i < a.size(); ++i) {
      if (std::isfinite(a[i]) && std::isfinite(k[i]) && std::fabs(a[i]) >= threshold)
        samples.push_back({f, i, k[i] / a[i]});
    }
  }
  if (samples.size() < kLookAlikeRatioMinSamples) return std::nullopt;
  std::optional<LookAlikeRatio> best;
  for (const std::string& name : flights.front()->names()) {
    if (excluded.count(name) || name == truth || is_position_channel(name) ||
        is_bookkeeping_channel(name) || !(is_aircraft_state(name) || is_motion_channel(name)))
      continue;
    bool everywhere = true;
    for (const FlightData* f : flights) everywhere = everywhere && f->has(name);
    if (!everywhere) continue;
    std::vector<double> ratio, value;
    ratio.reserve(samples.size());
    value.reserve(samples.size());
    std::vector<const double*> columns;  // each flight's column, looked up once
    for (const FlightData* f : flights) columns.push_back(f->column(name).data());
    for (const RatioSample& s : samples) {
      const double v = columns[s.flight][s.row];
      if (!std::isfinite(v)) continue;
      ratio.push_back(s.ratio);
      value.push_back(v);
    }
    if (ratio.size() < samples.size() * 9 / 10) continue;
    const auto n_pairs = static_cast<Eigen::Index>(ratio.size());
    const double r = pearson(Eigen::Map<const Eigen::VectorXd>(ratio.data(), n_pairs),
                             Eigen::Map<const Eigen::VectorXd>(value.data(), n_pairs));
    if (!(std::fabs(r) >= kLookAlikeRatioFollows) ||
        (best && std::fabs(r) <= std::fabs(best->correlation)))
      continue;
    best = LookAlikeRatio{
        "", joined(kept), joined(alike), name, r, pooled_relative_std(flights, name)};
  }
  return best;
}

// The non-empty subsets of `names` (all of them first); a set of more than three channels:
// itself only.
std::vector<std::set<std::string>> subsets(const std::set<std::string>& names) {
  std::vector<std::set<std::string>> out = {names};
  if (names.size() > 3) return out;
  const std::vector<std::string> v(names.begin(), names.end());
  const unsigned all = (1u << v.size()) - 1;
  for (unsigned mask = 1; mask < all; ++mask) {
    std::set<std::string> s;
    for (size_t i = 0; i < v.size(); ++i)
      if (mask & (1u << i)) s.insert(v[i]);
    out.push_back(std::move(s));
  }
  return out;
}

}  // namespace

std::optional<LookAlikeRatio> look_alike_ratio(const std::vector<const FlightData*>& flights,
                                               const std::set<std::string>& kept,
                                               const std::set<std::string>& alike,
                                               const std::string& truth) {
  if (flights.empty() || kept.empty() || alike.empty()) return std::nullopt;
  for (const std::string& x : kept)
    if (alike.count(x)) return std::nullopt;
  std::set<std::string> excluded = kept;
  excluded.insert(alike.begin(), alike.end());
  std::optional<LookAlikeRatio> best;
  for (const auto& k : subsets(kept)) {
    for (const auto& a : subsets(alike)) {
      auto ratio = ratio_of_products(flights, k, a, excluded, truth);
      if (ratio && (!best || std::fabs(ratio->correlation) > std::fabs(best->correlation)))
        best = std::move(ratio);
    }
  }
  return best;
}

}  // namespace magcomp::loop_steps
