// The residual's noise floor and the channel its power follows, against closed-form signals.
#include <gtest/gtest.h>

#include <cmath>
#include <random>

#include "../../src/core/diagnose/search.h"  // verdict_of
#include "magcomp/core/diagnose/residual_floor.h"

namespace magcomp {
namespace {

constexpr double kRate_hz = 10.0;

struct Residual {
  Eigen::VectorXd r, rpm, other;
  std::vector<int> unit;
};

// `n_units` held-out pieces of 3000 samples (5 min) each, with one sample in ten not held out
// between them; white noise of `sigma_nT`, a slow wander of `slow_nT` and a 2.2 Hz ripple whose
// amplitude is `ripple_nT` x rpm (a slowly varying, recorded channel) and whose phase drifts at
// random (not recorded).
Residual make(double sigma_nT, double slow_nT, double ripple_nT, unsigned seed) {
  const int n_units = 6, len = 3000, gap = 300;
  const Eigen::Index n = n_units * (len + gap);
  std::mt19937 rng(seed);
  std::normal_distribution<double> g(0.0, 1.0);
  Residual x;
  x.r.resize(n);
  x.rpm.resize(n);
  x.other.resize(n);
  x.unit.assign(static_cast<size_t>(n), -1);
  double phase = 0;
  for (Eigen::Index i = 0; i < n; ++i) {
    const double t = static_cast<double>(i) / kRate_hz;
    x.rpm[i] = 1.0 + 0.8 * std::sin(2 * M_PI * t / 97.0) * std::sin(2 * M_PI * t / 413.0);
    x.other[i] = std::cos(2 * M_PI * t / 151.0);
    phase += 0.05 * g(rng);
    x.r[i] = sigma_nT * g(rng) + slow_nT * std::sin(2 * M_PI * t / 40.0) +
             ripple_nT * x.rpm[i] * std::sin(2 * M_PI * 2.2 * t + phase);
    const Eigen::Index u = i / (len + gap);
    if (i % (len + gap) < len) x.unit[static_cast<size_t>(i)] = static_cast<int>(u);
  }
  return x;
}

ResidualFloor floor_of(const Residual& x) {
  std::vector<std::pair<std::string, Eigen::Map<const Eigen::VectorXd>>> ch;
  ch.emplace_back("rpm", Eigen::Map<const Eigen::VectorXd>(x.rpm.data(), x.rpm.size()));
  ch.emplace_back("other", Eigen::Map<const Eigen::VectorXd>(x.other.data(), x.other.size()));
  return residual_floor(x.r, x.unit, kRate_hz, ch);
}

TEST(ResidualFloor, WhiteNoiseIsItsOwnFloor) {
  for (double sigma : {0.05, 0.2, 1.0}) {
    const ResidualFloor f = floor_of(make(sigma, 0.0, 0.0, 3));
    std::printf("  white %.2f nT: residual %.4f nT, floor %.4f nT (%d segments)\n", sigma,
                f.residual_std_nT, f.floor_nT, f.segments);
    ASSERT_TRUE(f.computed);
    EXPECT_NEAR(f.floor_nT / sigma, 1.0, 0.05);
    EXPECT_TRUE(f.floor_channel.empty()) << f.floor_channel << " " << f.floor_correlation;
    EXPECT_NEAR(f.residual_std_nT / sigma, 1.0, 0.03);
    EXPECT_TRUE(f.amplitude_channel.empty()) << f.amplitude_channel;
  }
}

TEST(ResidualFloor, SlowStructureAndARippleDoNotRaiseTheFloor) {
  // 1 nT at 0.025 Hz (the aircraft's band) and a 0.8 nT ripple at 2.2 Hz, over 0.1 nT of noise.
  const ResidualFloor f = floor_of(make(0.1, 1.0, 0.8, 5));
  std::printf("  residual %.3f nT, floor %.4f nT; amplitude follows '%s' (rho %.2f, %d windows)\n",
              f.residual_std_nT, f.floor_nT, f.amplitude_channel.c_str(), f.amplitude_correlation,
              f.amplitude_windows);
  ASSERT_TRUE(f.computed);
  EXPECT_NEAR(f.floor_nT, 0.1, 0.012);
  EXPECT_GT(f.residual_std_nT, 5 * f.floor_nT);
  // The ripple's power follows rpm although its sign cannot be predicted from it.
  EXPECT_EQ(f.amplitude_channel, "rpm");
  EXPECT_GT(f.amplitude_correlation, 0.5);
}

TEST(ResidualFloor, AnEffectInSomeSegmentsOnlyIsNotTheFloor) {
  // 0.05 nT of white noise everywhere, and in the last of the six pieces a relay that chatters
  // (+-1 nT, switching at random from sample to sample) while its channel sits at its threshold:
  // broadband, but in a sixth of the segments only. The averaged spectrum would put the floor
  // near sqrt(0.05^2 + 1/6) = 0.41 nT; the typical segment's level is the sensor's.
  Residual x = make(0.05, 0.0, 0.0, 11);
  std::mt19937 rng(12);
  std::bernoulli_distribution coin(0.5);
  double relay = 1.0;
  for (Eigen::Index i = 5 * 3300; i < 5 * 3300 + 3000; ++i) {
    if (coin(rng)) relay = -relay;
    x.r[i] += relay;
  }
  const ResidualFloor f = floor_of(x);
  std::printf("  residual %.3f nT, floor %.4f nT (%d segments)\n", f.residual_std_nT, f.floor_nT,
              f.segments);
  ASSERT_TRUE(f.computed);
  EXPECT_NEAR(f.floor_nT, 0.05, 0.005);
  EXPECT_GT(f.residual_std_nT, 5 * f.floor_nT);
}

TEST(ResidualFloor, AChatterOnAChannelsNoiseIsAnEffectNotTheFloor) {
  // A relay switched by a recorded control that sits at its threshold: the control's noise
  // (0.05, white) flips it at random on every sample, a white chatter of +-0.3 nT times `rpm`
  // (the projection of the relay's field, slowly varying) beside the sensor's 0.02 nT. The
  // chatter is white: the residual is at its spectrum's white level, which therefore follows
  // rpm; the control's own level (0 on average) and an unrelated channel do not rank it.
  Residual x = make(0.0, 0.0, 0.0, 5);
  std::mt19937 rng(11);
  std::normal_distribution<double> g(0.0, 1.0);
  Eigen::VectorXd control(x.r.size());
  for (Eigen::Index i = 0; i < x.r.size(); ++i) {
    control[i] = 0.05 * g(rng);
    x.r[i] = 0.02 * g(rng) + 0.3 * x.rpm[i] * (control[i] > 0 ? 1.0 : -1.0);
  }
  std::vector<std::pair<std::string, Eigen::Map<const Eigen::VectorXd>>> ch;
  ch.emplace_back("other", Eigen::Map<const Eigen::VectorXd>(x.other.data(), x.other.size()));
  ch.emplace_back("control", Eigen::Map<const Eigen::VectorXd>(control.data(), control.size()));
  ch.emplace_back("rpm", Eigen::Map<const Eigen::VectorXd>(x.rpm.data(), x.rpm.size()));
  const ResidualFloor f = residual_floor(x.r, x.unit, kRate_hz, ch);
  std::printf("  residual %.3f nT, floor %.3f nT; floor follows '%s' (rho %.2f, %d segments)\n",
              f.residual_std_nT, f.floor_nT, f.floor_channel.c_str(), f.floor_correlation,
              f.segments);
  ASSERT_TRUE(f.computed);
  EXPECT_LE(f.residual_std_nT, 1.5 * f.floor_nT);  // at its white level: "complete" by that alone
  EXPECT_EQ(f.floor_channel, "rpm");
  EXPECT_GT(f.floor_correlation, 0.8);
  // The verdict: at its white level, but that level follows rpm: not "complete".
  Diagnosis dx;
  dx.floor = f;
  const std::string v = diagnose_search::verdict_of(dx, 0.03);
  std::printf("  verdict: %s\n", v.c_str());
  EXPECT_EQ(v.rfind("structure remains", 0), 0u) << v;
  EXPECT_NE(v.find("follows rpm"), std::string::npos) << v;
  dx.floor.floor_channel.clear();  // the same level, following nothing: the sensor's noise
  EXPECT_EQ(diagnose_search::verdict_of(dx, 0.03).rfind("complete", 0), 0u);
}

TEST(ResidualFloor, PositionChannelsAreNotSources) {
  for (const char* p : {"lat", "lon", "utm_x", "utm_y", "utm_z", "ins_lat", "ins_lon", "baro"})
    EXPECT_TRUE(is_position_channel(p)) << p;
  for (const char* c : {"cur_strb", "ins_acc_x", "pitch_rate", "vol_bat_1", "tas"})
    EXPECT_FALSE(is_position_channel(c)) << c;
}

TEST(ResidualFloor, TooShortForASpectrumIsNotComputed) {
  Eigen::VectorXd r = Eigen::VectorXd::Random(100);
  std::vector<int> unit(100, 0);
  EXPECT_FALSE(residual_floor(r, unit, kRate_hz, {}).computed);
}

}  // namespace
}  // namespace magcomp
