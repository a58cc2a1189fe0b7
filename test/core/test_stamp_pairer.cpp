// The stamp pairer (two halves of one sample on two topics) and the INS attitude conventions the
// navigator reads its halves with.
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <random>
#include <string>
#include <vector>

#include "magcomp/core/geo/attitude.h"
#include "magcomp/core/stream/stamp_pairer.h"

namespace magcomp {
namespace {

TEST(StampPairer, HalvesPairInEitherOrderAndKeepTheirValues) {
  StampPairer<double, std::string> p;
  EXPECT_FALSE(p.add_first(1.0, 10.0));
  EXPECT_FALSE(p.add_second(2.0, "b"));
  const auto a = p.add_second(1.0, "a");
  ASSERT_TRUE(a);
  EXPECT_EQ(a->t_s, 1.0);
  EXPECT_EQ(a->first, 10.0);
  EXPECT_EQ(a->second, "a");
  const auto b = p.add_first(2.0, 20.0);
  ASSERT_TRUE(b);
  EXPECT_EQ(b->first, 20.0);
  EXPECT_EQ(b->second, "b");
  EXPECT_EQ(p.counts().paired, 2);
  EXPECT_EQ(p.waiting(), 0u);
}

TEST(StampPairer, HalvesThatCanNoLongerPairAreDroppedAndCountedBySide) {
  PairerSettings s;
  s.max_age_s = 5.0;
  StampPairer<int, int> p(s);
  p.add_first(0.0, 0);   // its second half never comes
  p.add_second(0.5, 0);  // its first half never comes
  p.add_first(1.0, 1);
  EXPECT_TRUE(p.add_second(1.0, 1));  // a pair at 1 s: both older halves go
  EXPECT_EQ(p.counts().first_dropped, 1);
  EXPECT_EQ(p.counts().second_dropped, 1);
  p.add_first(2.0, 2);  // waits ...
  p.add_first(7.5, 7);  // ... more than 5 s behind the newest stamp: dropped
  EXPECT_EQ(p.counts().first_dropped, 2);
  EXPECT_EQ(p.waiting(), 1u);
  p.clear();  // a restart: forgotten, not counted
  EXPECT_EQ(p.waiting(), 0u);
  EXPECT_EQ(p.counts().first_dropped, 2);
  // A bound on what is held, whatever the stamps.
  PairerSettings small;
  small.max_held = 3;
  StampPairer<int, int> q(small);
  for (int k = 0; k < 10; ++k) q.add_first(0.01 * k, k);
  EXPECT_EQ(q.waiting(), 3u);
  EXPECT_EQ(q.counts().first_dropped, 7);
}

TEST(StampPairer, TwoInOrderTopicsWithDelaysPairEveryCompleteSampleOnce) {
  // 2000 samples at 10 Hz; the first half missing on every 7th, the second on every 11th; each
  // topic delivered in order with its own random delay of 0..0.8 s, the two interleaved by
  // arrival. Every sample with both halves pairs exactly once with its own values; every half
  // without its partner is dropped or still waiting; none is lost.
  std::mt19937 rng(7);
  std::uniform_real_distribution<double> delay(0.0, 0.8);
  struct Arrival {
    double at_s, t_s;
    bool first;
  };
  std::vector<Arrival> arrivals;
  double last_a = 0, last_b = 0;
  long complete = 0, lonely = 0;
  for (int k = 0; k < 2000; ++k) {
    const double t = 0.1 * k;
    const bool has_a = k % 7 != 0, has_b = k % 11 != 0;
    complete += has_a && has_b;
    lonely += has_a != has_b;
    if (has_a) arrivals.push_back({last_a = std::max(last_a, t + delay(rng)), t, true});
    if (has_b) arrivals.push_back({last_b = std::max(last_b, t + delay(rng)), t, false});
  }
  std::stable_sort(arrivals.begin(), arrivals.end(),
                   [](const Arrival& x, const Arrival& y) { return x.at_s < y.at_s; });
  StampPairer<double, double> p;
  long pairs = 0;
  for (const Arrival& a : arrivals) {
    const auto pair = a.first ? p.add_first(a.t_s, 2.0 * a.t_s) : p.add_second(a.t_s, 3.0 * a.t_s);
    if (!pair) continue;
    ++pairs;
    EXPECT_EQ(pair->first, 2.0 * pair->t_s);
    EXPECT_EQ(pair->second, 3.0 * pair->t_s);
  }
  EXPECT_EQ(pairs, complete);
  EXPECT_EQ(p.counts().paired, complete);
  EXPECT_EQ(p.counts().first_dropped + p.counts().second_dropped + static_cast<long>(p.waiting()),
            lonely);
}

TEST(InsAttitude, ConventionsAgreeWithTheAxesTheyName) {
  // Level, heading north: base_link's x (forward) points north in ENU, its z up.
  const double d = M_PI / 180;
  Eigen::Quaterniond q = enu_orientation(0, 0, 0);
  EXPECT_NEAR((q * Eigen::Vector3d::UnitX() - Eigen::Vector3d(0, 1, 0)).norm(), 0, 1e-15);
  EXPECT_NEAR((q * Eigen::Vector3d::UnitZ() - Eigen::Vector3d(0, 0, 1)).norm(), 0, 1e-15);
  // Heading east (yaw 90 deg, clockwise from north): forward points east.
  q = enu_orientation(0, 0, 90 * d);
  EXPECT_NEAR((q * Eigen::Vector3d::UnitX() - Eigen::Vector3d(1, 0, 0)).norm(), 0, 1e-15);
  // Nose up 10 deg (pitch > 0 in NED/FRD): forward climbs by sin 10 deg.
  q = enu_orientation(0, 10 * d, 0);
  EXPECT_NEAR((q * Eigen::Vector3d::UnitX()).z(), std::sin(10 * d), 1e-15);
  // Right wing down 20 deg (roll > 0): base_link's y (the left wing) rises by sin 20 deg.
  q = enu_orientation(20 * d, 0, 0);
  EXPECT_NEAR((q * Eigen::Vector3d::UnitY()).z(), std::sin(20 * d), 1e-15);
  // And back: any attitude short of the vertical round-trips.
  std::mt19937 rng(3);
  std::uniform_real_distribution<double> u(-1.0, 1.0);
  for (int k = 0; k < 1000; ++k) {
    const Eigen::Vector3d rpy(M_PI * u(rng), 1.5 * u(rng), M_PI * u(rng));
    const Eigen::Vector3d back = ned_attitude(enu_orientation(rpy.x(), rpy.y(), rpy.z()));
    for (int i = 0; i < 3; ++i)
      EXPECT_NEAR(std::remainder(back[i] - rpy[i], 2 * M_PI), 0, 1e-12) << k << " " << i;
  }
}

TEST(InsAttitude, ACovarianceTurnsFromNedToEnu) {
  Eigen::Matrix3d ned;
  ned << 4, 1, 0.5, 1, 9, 0.25, 0.5, 0.25, 16;  // north, east, down
  const Eigen::Matrix3d enu = ned_to_enu_covariance(ned);
  EXPECT_EQ(enu(0, 0), 9);      // east
  EXPECT_EQ(enu(1, 1), 4);      // north
  EXPECT_EQ(enu(2, 2), 16);     // up
  EXPECT_EQ(enu(0, 1), 1);      // north-east correlation kept
  EXPECT_EQ(enu(0, 2), -0.25);  // east-up = -(east-down)
  EXPECT_EQ(enu(1, 2), -0.5);   // north-up = -(north-down)
}

}  // namespace
}  // namespace magcomp
