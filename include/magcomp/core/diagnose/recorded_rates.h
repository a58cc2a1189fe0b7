// magcomp: sources whose rate of change another recorded source is (an INS angle and its rate
// gyro, the airspeed and the longitudinal acceleration): a term of the derivative names the
// effect by the recorded rate.
#pragma once

#include <string>
#include <vector>

#include "magcomp/core/io/flight_data.h"

namespace magcomp {

/// A source `channel` whose rate of change (per s, central differences) is the recorded `rate`:
/// their means over kTwinWindow_s blocks have |r| >= kTwinCorrelation (Pearson, `correlation`)
/// on the flight, so no term of the flight tells `channel|d` from `rate`.
struct RecordedRate {
  std::string channel, rate;
  double correlation = 0;
};

/// Each of `sources` (recorded channels of `data`) whose rate of change is another of them, with
/// the most alike such rate; none where the flight is shorter than 50 blocks. A channel's blocks
/// need half their samples finite.
std::vector<RecordedRate> recorded_rates(const FlightData& data,
                                         const std::vector<std::string>& sources);

}  // namespace magcomp
