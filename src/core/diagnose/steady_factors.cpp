// magcomp: the channels a kept term's field may scale with unseen: recorded states that the
// loop's flights hold so steady that the term times one of them differs from the term alone by
// less than the resolution (LoopRound::steady_factors); and a channel's relative std over flights,
// which the look-alike ratio reports too.
#include <algorithm>
#include <cmath>

#include "loop_steps.h"
#include "magcomp/core/diagnose/channel_noise.h"
#include "magcomp/core/io/channel_kinds.h"

namespace magcomp::loop_steps {

double pooled_relative_std(const std::vector<const FlightData*>& flights, const std::string& name) {
  double n = 0, sum = 0, sum2 = 0;
  for (const FlightData* f : flights) {
    const FlightData::Column x = f->column(name);
    for (Eigen::Index i = 0; i < x.size(); ++i) {
      if (!std::isfinite(x[i])) continue;
      n += 1;
      sum += x[i];
      sum2 += x[i] * x[i];
    }
  }
  if (n < 2) return NAN;
  const double mean = sum / n;
  const double sd = std::sqrt(std::max(sum2 / n - mean * mean, 0.0));
  return std::fabs(mean) > 0 ? sd / std::fabs(mean) : NAN;
}

std::vector<std::pair<std::string, double>> steady_factors(
    const std::vector<const FlightData*>& flights, const std::set<std::string>& kept_channels,
    const std::string& truth, double term_nT, double resolution_nT) {
  std::vector<std::pair<std::string, double>> out;
  if (flights.empty() || kept_channels.empty() || !(term_nT > 0)) return out;
  for (const std::string& name : flights.front()->names()) {
    if (kept_channels.count(name) || name == truth || !is_aircraft_state(name)) continue;
    // Pooled over the flights' finite samples; a channel missing from a flight, more than a
    // tenth NaN on one, constant, or recording a constant and its noise only is no source the
    // search reads (diagnose's source_fields), and none here.
    bool usable = true;
    for (const FlightData* f : flights) {
      if (!f->has(name)) {
        usable = false;
        break;
      }
      const FlightData::Column x = f->column(name);
      Eigen::Index finite = 0;
      double lo = INFINITY, hi = -INFINITY;
      for (Eigen::Index i = 0; i < x.size(); ++i) {
        if (!std::isfinite(x[i])) continue;
        ++finite;
        lo = std::min(lo, x[i]);
        hi = std::max(hi, x[i]);
      }
      if (!(hi > lo) || finite < x.size() * 9 / 10 || records_noise_only(x, f->dt_s())) {
        usable = false;
        break;
      }
    }
    if (!usable) continue;
    const double relative = pooled_relative_std(flights, name);
    if (!std::isfinite(relative)) continue;
    // The term times x is the term times x's mean plus the term times x's deviation: the
    // latter's std is at most the term's std times x's relative std (x independent of it),
    // and below the resolution no held-out line tells the two apart.
    if (relative * term_nT < resolution_nT) out.emplace_back(name, relative);
  }
  std::sort(out.begin(), out.end(),
            [](const auto& a, const auto& b) { return a.second < b.second; });
  return out;
}

}  // namespace magcomp::loop_steps
