// slow_to_noise_ratio / records_noise_only against closed-form channels: a rail that reads a
// constant plus white noise, a switched current, a drifting battery voltage, a clean switch.
#include <gtest/gtest.h>

#include <cmath>
#include <random>

#include "magcomp/core/diagnose/channel_noise.h"

namespace magcomp {
namespace {

constexpr double kDt_s = 0.1;
constexpr Eigen::Index kN = 15000;  // 25 min at 10 Hz

Eigen::VectorXd white(double sigma, unsigned seed) {
  std::mt19937 rng(seed);
  std::normal_distribution<double> g(0.0, sigma);
  Eigen::VectorXd x(kN);
  for (Eigen::Index i = 0; i < kN; ++i) x[i] = g(rng);
  return x;
}

TEST(ChannelNoise, ARailOfAConstantAndWhiteNoiseRecordsNoiseOnly) {
  // 15 V with 5 mV of white noise, the simulator's vol_res_p: the block means' variance is the
  // noise's over 100 samples, a ratio of 1 within its sampling spread over 150 blocks.
  for (unsigned seed : {1u, 2u, 3u}) {
    const Eigen::VectorXd rail = Eigen::VectorXd::Constant(kN, 15.0) + white(0.005, seed);
    const double r = slow_to_noise_ratio(rail, kDt_s), v = variance_to_noise_ratio(rail);
    std::printf("  rail, seed %u: slow ratio %.3f, variance ratio %.4f\n", seed, r, v);
    EXPECT_NEAR(r, 1.0, 0.4);
    EXPECT_NEAR(v, 1.0, 0.05);
    EXPECT_TRUE(records_noise_only(rail, kDt_s));
  }
}

TEST(ChannelNoise, SwitchedDriftingAndCleanChannelsHoldMoreThanTheirNoise) {
  Eigen::VectorXd switched(kN), drifting(kN), clean(kN);
  const Eigen::VectorXd n1 = white(0.05, 4), n2 = white(0.005, 5);
  for (Eigen::Index i = 0; i < kN; ++i) {
    const double t = static_cast<double>(i) * kDt_s;
    switched[i] = ((i / 370) % 2 ? 2.0 : 0.0) + n1[i];  // a load on for 37 s in 74
    drifting[i] = 27.5 - 0.3 * t / 1500.0 + n2[i];      // a battery losing 0.3 V in the flight
    clean[i] = (i / 370) % 2 ? 1.0 : 0.0;               // a switch recorded without noise
  }
  const double rs = slow_to_noise_ratio(switched, kDt_s), rd = slow_to_noise_ratio(drifting, kDt_s),
               rc = slow_to_noise_ratio(clean, kDt_s);
  std::printf("  ratios: switched %.0f, drifting %.0f, clean %g\n", rs, rd, rc);
  EXPECT_GT(rs, 100.0);
  EXPECT_GT(rd, 100.0);
  EXPECT_TRUE(std::isinf(rc));
  EXPECT_FALSE(records_noise_only(switched, kDt_s));
  EXPECT_FALSE(records_noise_only(drifting, kDt_s));
  EXPECT_FALSE(records_noise_only(clean, kDt_s));
  // A rate swinging at 0.2 Hz (a maneuver's): its 10 s means average it out, its variance
  // does not.
  Eigen::VectorXd rate(kN);
  const Eigen::VectorXd n3 = white(0.2, 7);
  for (Eigen::Index i = 0; i < kN; ++i)
    rate[i] = std::sin(2 * M_PI * 0.2 * static_cast<double>(i) * kDt_s) + n3[i];
  const double rr = slow_to_noise_ratio(rate, kDt_s), rv = variance_to_noise_ratio(rate);
  std::printf("  rate at 0.2 Hz: slow ratio %.2f, variance ratio %.1f\n", rr, rv);
  EXPECT_LT(rr, kNoiseOnlySlowRatio);
  EXPECT_GT(rv, 3.0);
  EXPECT_FALSE(records_noise_only(rate, kDt_s));
  // A constant says nothing either way (source_fields skips it as constant); too short: unknown.
  EXPECT_TRUE(std::isnan(slow_to_noise_ratio(Eigen::VectorXd::Constant(kN, 3.0), kDt_s)));
  EXPECT_TRUE(std::isnan(slow_to_noise_ratio(white(1.0, 6).head(500), kDt_s)));
  EXPECT_FALSE(records_noise_only(white(1.0, 6).head(500), kDt_s));
}

}  // namespace
}  // namespace magcomp
