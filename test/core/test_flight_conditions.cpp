// Flight conditions and heading sectors on a constructed flight whose every segment is known:
// straight and level, a turn, a climb, a roll maneuver; sectors at and around their borders.
#include <gtest/gtest.h>

#include <cmath>

#include "magcomp/core/flight_conditions.h"

namespace magcomp {
namespace {

// 10 Hz, four 60 s segments: level, turn (3 deg/s), climb (5 m/s), roll oscillation (5 deg/s
// amplitude, 8 s period).
FlightData four_segments() {
  const Eigen::Index n = 2400;
  Eigen::VectorXd tt(n), yaw_rate = Eigen::VectorXd::Zero(n), roll_rate = Eigen::VectorXd::Zero(n),
                         pitch_rate = Eigen::VectorXd::Zero(n), vu = Eigen::VectorXd::Zero(n);
  for (Eigen::Index i = 0; i < n; ++i) {
    tt[i] = 1000.0 + 0.1 * static_cast<double>(i);
    const Eigen::Index segment = i / 600;
    if (segment == 1) yaw_rate[i] = 3.0;
    if (segment == 2) vu[i] = 5.0;
    if (segment == 3) roll_rate[i] = 5.0 * std::sin(2 * M_PI * 0.1 * static_cast<double>(i) / 8.0);
  }
  FlightData f;
  f.set("tt", tt);
  f.set("yaw_rate", yaw_rate);
  f.set("roll_rate", roll_rate);
  f.set("pitch_rate", pitch_rate);
  f.set("ins_vu", vu);
  return f;
}

TEST(FlightConditions, EachKnownSegmentIsClassifiedAsWhatItIs) {
  const auto c = classify_conditions(four_segments());
  ASSERT_EQ(c.size(), 2400u);
  // Away from the borders (the window is 6 s: 30 samples either side).
  for (size_t i = 50; i < 550; ++i) EXPECT_EQ(c[i], FlightCondition::kStraightLevel) << i;
  for (size_t i = 650; i < 1150; ++i) EXPECT_EQ(c[i], FlightCondition::kTurn) << i;
  for (size_t i = 1250; i < 1750; ++i) EXPECT_EQ(c[i], FlightCondition::kClimbDescent) << i;
  for (size_t i = 1850; i < 2350; ++i) EXPECT_EQ(c[i], FlightCondition::kRollManeuver) << i;
  EXPECT_STREQ(condition_name(FlightCondition::kTurn), "turn");
}

TEST(FlightConditions, HeadingSectorsAre45DegreesCentredOnTheirDirection) {
  const Eigen::Index n = 10;
  Eigen::VectorXd tt(n), yaw(n);
  const double values[] = {0.0, 22.4, 22.6, 90.0, 180.0, 337.6, -90.0, 719.0, NAN, -22.4};
  const int sectors[] = {0, 0, 1, 2, 4, 0, 6, 0, -1, 0};
  for (Eigen::Index i = 0; i < n; ++i) {
    tt[i] = static_cast<double>(i);
    yaw[i] = values[i];
  }
  FlightData f;
  f.set("tt", tt);
  f.set("ins_yaw", yaw);
  const std::vector<int> s = heading_sectors(f);
  for (Eigen::Index i = 0; i < n; ++i)
    EXPECT_EQ(s[static_cast<size_t>(i)], sectors[i]) << values[i];
  EXPECT_STREQ(sector_name(2), "E");
}

}  // namespace
}  // namespace magcomp
