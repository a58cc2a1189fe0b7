// Flight conditions and heading sectors on a constructed flight whose every segment is known:
// straight and level, a turn, a climb, a roll maneuver; sectors at and around their borders.
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>

#include "magcomp/core/evaluate/flight_conditions.h"

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

// The definition, one sample at a time over whole-series prefix sums: what the block-wise
// classification must give bit for bit.
std::vector<FlightCondition> classify_by_definition(const FlightData& d, double window_s) {
  const Eigen::Index n = d.size();
  const Eigen::Index w = std::max<Eigen::Index>(3, std::llround(window_s / d.dt_s()));
  auto stats = [&](const char* name, Eigen::Index i, double* mean, double* rms) {
    *mean = *rms = 0.0;
    if (!d.has(name)) return;
    const auto x = d.column(name);
    const Eigen::Index a = std::max<Eigen::Index>(0, i - w / 2), b = std::min(n, i + w / 2 + 1);
    double s1a = 0, s2a = 0, s1b = 0, s2b = 0, s1 = 0, s2 = 0;
    for (Eigen::Index j = 0; j <= b; ++j) {  // prefix sums in order, read at a and b
      if (j == a) s1a = s1, s2a = s2;
      if (j == b) s1b = s1, s2b = s2;
      if (j == b) break;
      const double v = std::isfinite(x[j]) ? x[j] : 0.0;
      s1 += v;
      s2 += v * v;
    }
    const double k = static_cast<double>(b - a);
    *mean = (s1b - s1a) / k;
    *rms = std::sqrt(std::max(0.0, (s2b - s2a) / k - *mean * *mean));
  };
  std::vector<FlightCondition> out(static_cast<size_t>(n));
  for (Eigen::Index i = 0; i < n; ++i) {
    double pm, p, rm, r, ym, y, vm, vr;
    stats("pitch_rate", i, &pm, &p);
    stats("roll_rate", i, &rm, &r);
    stats("yaw_rate", i, &ym, &y);
    stats("ins_vu", i, &vm, &vr);
    FlightCondition c = FlightCondition::kStraightLevel;
    if (std::abs(ym) > 1.5) {
      c = FlightCondition::kTurn;
    } else if (std::abs(vm) > 2.0) {
      c = FlightCondition::kClimbDescent;
    } else if (std::max({p, r, y}) > 1.0) {
      c = (p >= r && p >= y) ? FlightCondition::kPitchManeuver
          : (r >= y)         ? FlightCondition::kRollManeuver
                             : FlightCondition::kYawManeuver;
    }
    out[static_cast<size_t>(i)] = c;
  }
  return out;
}

TEST(FlightConditions, BlockWiseClassificationEqualsTheDefinitionSampleBySample) {
  // 9,000 samples (blocks of 4,096 and a remainder) in 100 s segments: level, pitch, roll and
  // yaw oscillations, a turn, a climb, level again, pitch and roll together, a yaw oscillation
  // in a slow turn; NaN and Inf here and there; without a vertical-speed channel, then with one.
  const Eigen::Index n = 9000;
  Eigen::VectorXd tt(n), pitch(n), roll(n), yaw(n), vu(n);
  for (Eigen::Index i = 0; i < n; ++i) {
    const double t = 0.1 * static_cast<double>(i);
    const int segment = static_cast<int>(i / 1000);
    tt[i] = 5000.0 + t;
    const double osc = 3.0 * std::sin(0.9 * t);
    pitch[i] = (segment == 1 || segment == 7) ? osc : 0.05 * std::sin(3.1 * t);
    roll[i] = (segment == 2 || segment == 7) ? 0.8 * osc : 0.05 * std::cos(2.3 * t);
    yaw[i] = (segment == 3 || segment == 8) ? 2.0 * std::sin(1.3 * t) : 0.0;
    if (segment == 4) yaw[i] = 3.0;
    if (segment == 8) yaw[i] += 1.2;
    vu[i] = segment == 5 ? 4.0 : 0.1 * std::sin(0.5 * t);
    if (i % 997 < 4) pitch[i] = NAN;
    if (i % 1500 == 7) roll[i] = INFINITY;
  }
  FlightData f;
  f.set("tt", tt);
  f.set("pitch_rate", pitch);
  f.set("roll_rate", roll);
  f.set("yaw_rate", yaw);
  for (int with_vu = 0; with_vu < 2; ++with_vu) {
    if (with_vu) f.set("ins_vu", vu);
    const auto fast = classify_conditions(f);
    const auto slow = classify_by_definition(f, 6.0);
    ASSERT_EQ(fast.size(), slow.size());
    std::vector<int> seen(kConditionCount, 0);
    for (size_t i = 0; i < fast.size(); ++i) {
      ASSERT_EQ(fast[i], slow[i]) << "sample " << i << (with_vu ? " with ins_vu" : "");
      seen[static_cast<size_t>(fast[i])]++;
    }
    for (int c = 0; c < kConditionCount; ++c) {
      if (c == static_cast<int>(FlightCondition::kClimbDescent) && !with_vu) continue;
      EXPECT_GT(seen[static_cast<size_t>(c)], 0) << condition_name(static_cast<FlightCondition>(c));
    }
  }
}

TEST(FlightConditions, TheHeadingSectorEqualsItsRemainderFormulaEverywhere) {
  // Headings over several turns either way, at and beside every sector border.
  long checked = 0;
  for (int turn = -3; turn <= 3; ++turn) {
    for (int border = 0; border < 16; ++border) {
      const double at = 360.0 * turn + 22.5 * border;
      for (double yaw : {at, std::nextafter(at, -1e9), std::nextafter(at, 1e9), at + 1e-9,
                         at - 1e-9, at + 10.0}) {
        const double h = std::fmod(std::fmod(yaw, 360.0) + 360.0 + 22.5, 360.0);
        EXPECT_EQ(heading_sector(yaw), static_cast<int>(h / 45.0) % 8) << yaw;
        ++checked;
      }
    }
  }
  EXPECT_EQ(heading_sector(NAN), -1);
  EXPECT_EQ(heading_sector(-INFINITY), -1);
  EXPECT_EQ(checked, 7 * 16 * 6);
}

}  // namespace
}  // namespace magcomp
