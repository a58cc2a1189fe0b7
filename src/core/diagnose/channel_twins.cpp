// magcomp: recorded channels no flight tells apart.
#include "magcomp/core/diagnose/channel_twins.h"

#include <algorithm>
#include <cmath>
#include <map>

#include "magcomp/core/io/channel_kinds.h"
#include "magcomp/core/math/correlation.h"
#include "magcomp/core/math/timeseries.h"

namespace magcomp {

namespace {

// Whether a recorded channel may carry an effect of its own: an aircraft state or motion (not a
// position, an earth-frame velocity, a magnetometer or bookkeeping).
bool may_carry_an_effect(const std::string& name) {
  if (is_position_channel(name) || is_earth_frame_velocity(name)) return false;
  return is_aircraft_state(name) || is_motion_channel(name);
}

}  // namespace

std::vector<ChannelTwin> channel_twins(const std::string& channel,
                                       const std::vector<const FlightData*>& flights,
                                       const std::set<std::string>& skip) {
  std::map<std::string, double> least;  // each candidate's least |r| over the flights so far
  bool first = true;
  for (const FlightData* f : flights) {
    if (!f->has(channel) || !(f->dt_s() > 0)) return {};
    const auto half = static_cast<Eigen::Index>(std::lround(0.5 * kTwinWindow_s / f->dt_s()));
    const Eigen::VectorXd x = moving_average(f->column(channel), half);
    std::map<std::string, double> here;
    for (const std::string& y : f->names()) {
      if (y == channel || skip.count(y) || !may_carry_an_effect(y)) continue;
      if (!first && !least.count(y)) continue;  // another flight tells them apart
      const double r = std::abs(pearson_where_finite(x, moving_average(f->column(y), half), 50));
      if (!(r >= kTwinCorrelation)) continue;
      here[y] = first ? r : std::min(r, least[y]);
    }
    least = std::move(here);
    first = false;
    if (least.empty()) break;
  }
  std::vector<ChannelTwin> out;
  for (const auto& [y, r] : least) out.push_back({channel, y, r});
  std::sort(out.begin(), out.end(), [](const ChannelTwin& a, const ChannelTwin& b) {
    return a.correlation > b.correlation || (a.correlation == b.correlation && a.twin < b.twin);
  });
  return out;
}

}  // namespace magcomp
