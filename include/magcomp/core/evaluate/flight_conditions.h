// magcomp: what the aircraft was doing at each sample (for error statistics by condition).
#pragma once

#include <Eigen/Core>
#include <cmath>
#include <cstdint>
#include <string>
#include <vector>

#include "magcomp/core/io/flight_data.h"

namespace magcomp {

/// Flight condition of one sample, from the INS (rates in deg/s, vertical speed in m/s).
enum class FlightCondition : uint8_t {
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

/// Online detection of calibration maneuvers (pitch, roll, yaw oscillations flown on a straight
/// leg) from the attitude rates, causal: over the last window_s seconds, some rate's oscillation
/// (rms about its mean) exceeds threshold_dps while the mean yaw rate stays below 1.5 deg/s (not a
/// turn). Rates in deg/s, time in s.
class ManeuverDetector {
 public:
  explicit ManeuverDetector(double window_s = 6.0, double threshold_dps = 1.0)
      : window_s_(window_s), threshold_dps_(threshold_dps) {}
  /// Adds the rates at time t_s (increasing); returns whether a calibration maneuver is under way.
  bool update(double t_s, double pitch_rate_dps, double roll_rate_dps, double yaw_rate_dps);
  void reset() { samples_.clear(); }

 private:
  struct Rates {
    double t, p, r, y;
  };
  std::vector<Rates> samples_;
  double window_s_, threshold_dps_;
};

/// Heading sector index 0..7 (N, NE, E, SE, S, SW, W, NW; 45 deg each) of a heading (deg, any
/// turn), -1 if not finite: the sector of fmod(fmod(yaw, 360) + 360 + 22.5, 360) / 45, computed
/// without the remainders where they are plain subtractions (the same numbers).
inline int heading_sector(double yaw_deg) {
  if (!std::isfinite(yaw_deg)) return -1;
  const double r = std::abs(yaw_deg) < 360.0 ? yaw_deg : std::fmod(yaw_deg, 360.0);
  double h = r + 360.0 + 22.5;  // in (22.5, 742.5): subtracting 360 or 720 is exact
  if (h >= 720.0) {
    h -= 720.0;
  } else if (h >= 360.0) {
    h -= 360.0;
  }
  return static_cast<int>(h / 45.0) % 8;
}
/// heading_sector() of every sample's ins_yaw (all -1 without it).
std::vector<int> heading_sectors(const FlightData& data);
const char* sector_name(int sector);

}  // namespace magcomp
