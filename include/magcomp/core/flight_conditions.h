// magcomp: what the aircraft was doing at each sample (for error statistics by condition).
#pragma once

#include <Eigen/Core>
#include <string>
#include <vector>

#include "magcomp/core/flight_data.h"

namespace magcomp {

/// Flight condition of one sample, from the INS (rates in deg/s, vertical speed in m/s).
enum class FlightCondition : int {
  kStraightLevel = 0,
  kTurn = 1,
  kClimbDescent = 2,
  kPitchManeuver = 3,
  kRollManeuver = 4,
  kYawManeuver = 5,
};
const char* condition_name(FlightCondition c);
constexpr int kConditionCount = 6;

/// Classifies every sample over a centred window of window_s seconds: a turn when the mean yaw
/// rate exceeds 1.5 deg/s; a climb or descent when the mean vertical speed exceeds 2 m/s; else a
/// pitch / roll / yaw maneuver when that rate's oscillation (rms about its mean) exceeds 1 deg/s
/// and dominates; else straight and level. Needs pitch_rate, roll_rate, yaw_rate, ins_vu
/// (missing ones count as zero).
std::vector<FlightCondition> classify_conditions(const FlightData& data, double window_s = 6.0);

/// Heading sector index 0..7 (N, NE, E, SE, S, SW, W, NW; 45 deg each) from ins_yaw (deg), -1 if
/// unknown.
std::vector<int> heading_sectors(const FlightData& data);
const char* sector_name(int sector);

}  // namespace magcomp
