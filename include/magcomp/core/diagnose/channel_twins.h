// magcomp: recorded channels no flight tells apart (a bus's two voltage taps, two batteries on one
// charge curve): an effect found through one may as well be an effect of the other.
#pragma once

#include <set>
#include <string>
#include <vector>

#include "magcomp/core/io/flight_data.h"

namespace magcomp {

/// Channels are compared smoothed over this window (s): each sensor's own noise, which a term's
/// low-pass and the fit average away, would otherwise set two taps of one bus apart.
constexpr double kTwinWindow_s = 5.0;
/// Two channels whose smoothed values have at least this |r| (Pearson) on every flight are twins.
constexpr double kTwinCorrelation = 0.999;

/// A channel and one it cannot be told from: their values smoothed over kTwinWindow_s have
/// |r| >= kTwinCorrelation on every flight; `correlation` is the least |r| over the flights.
struct ChannelTwin {
  std::string channel, twin;
  double correlation = 0;
};

/// The twins of `channel` among the flights' recorded aircraft states and motion channels (not a
/// position, an earth-frame velocity, a magnetometer or bookkeeping; not in `skip`), most alike
/// first. Empty when a flight does not record `channel` or it holds steady there (a constant's
/// noise follows nothing).
std::vector<ChannelTwin> channel_twins(const std::string& channel,
                                       const std::vector<const FlightData*>& flights,
                                       const std::set<std::string>& skip = {});

}  // namespace magcomp
