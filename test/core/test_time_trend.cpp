// time_trend: which recorded channels follow a smooth curve of the flight's time, on closed-form
// columns and on the simulator's electrical system.
#include <gtest/gtest.h>

#include <cmath>
#include <cstdio>
#include <random>

#include "discovery_run.h"
#include "magcomp/core/diagnose/term_support.h"
#include "magcomp/core/diagnose/time_trend.h"
#include "magcomp/core/fit/model_fit.h"
#include "magcomp/core/sim/simulator.h"
#include "scenario_cache.h"
#include "synthetic_flight.h"

namespace magcomp {
namespace {

constexpr double kDt_s = 0.1;

TEST(TimeTrend, AChargeCurveFollowsTimeASwitchedLoadAndASineDoNot) {
  // Two hours at 10 Hz: a battery's charge current 2 exp(-t / 1800 s) A with 0.02 A of white
  // noise; a load switched on and off every 137 s; a sine of 600 s; a random walk.
  const Eigen::Index n = 72000;
  std::mt19937_64 rng(3);
  std::normal_distribution<double> normal(0.0, 1.0);
  Eigen::VectorXd charge(n), load(n), sine(n), walk(n);
  double w = 0;
  for (Eigen::Index i = 0; i < n; ++i) {
    const double t = kDt_s * static_cast<double>(i);
    charge[i] = 2.0 * std::exp(-t / 1800.0) + 0.02 * normal(rng);
    load[i] = (static_cast<long>(t / 137.0) % 2 ? 3.0 : 0.5) + 0.02 * normal(rng);
    sine[i] = std::sin(2 * M_PI * t / 600.0) + 0.02 * normal(rng);
    w += 0.01 * normal(rng);
    walk[i] = w;
  }
  const double s_charge = time_trend_share(charge, kDt_s), s_load = time_trend_share(load, kDt_s),
               s_sine = time_trend_share(sine, kDt_s), s_walk = time_trend_share(walk, kDt_s);
  std::printf("  charge %.5f, switched load %.5f, 600 s sine %.5f, random walk %.5f\n", s_charge,
              s_load, s_sine, s_walk);
  EXPECT_GE(s_charge, kTimeTrendShare);
  EXPECT_LT(s_load, 0.1);
  EXPECT_LT(s_sine, 0.1);
  EXPECT_LT(s_walk, kTimeTrendShare);
  // A cubic in time is a cubic's own curve, whatever its noise averages to over 5 s blocks.
  Eigen::VectorXd cubic(n);
  for (Eigen::Index i = 0; i < n; ++i) {
    const double u = static_cast<double>(i) / static_cast<double>(n);
    cubic[i] = 1 + u - 3 * u * u + 2 * u * u * u;
  }
  EXPECT_NEAR(time_trend_share(cubic, kDt_s), 1.0, 1e-12);
  // Too short (fewer than 20 blocks), or constant: no share.
  EXPECT_TRUE(std::isnan(time_trend_share(charge.head(90), kDt_s)));
  EXPECT_TRUE(std::isnan(time_trend_share(Eigen::VectorXd::Constant(n, 1.0), kDt_s)));
  // A NaN block is skipped, not spread.
  Eigen::VectorXd holed = charge;
  holed.segment(1000, 30).setConstant(NAN);
  EXPECT_NEAR(time_trend_share(holed, kDt_s), s_charge, 1e-3);
}

TEST(TimeTrend, TheSimulatorsBatteriesFollowTheFlightsTimeItsLoadsDoNot) {
  // The simulator's batteries charge on fixed curves of the time since the start (currents
  // 2 exp(-t / 1800 s), voltages 0.5 (1 - exp(-t / 2400 s)) above their level): any drift of
  // that shape reads as well through them. Its switched loads and the INS do not.
  sim::Scenario s = sim::load_scenario(test::source_dir() + "/config/scenarios/lag.yaml");
  s.aircraft_states = true;
  const sim::Simulation sim = sim::simulate(s, Igrf::installed());
  const FlightData& f = sim.flight;
  for (const char* c : {"cur_bat_1", "cur_bat_2", "vol_bat_1", "vol_bat_2"}) {
    const std::vector<TimeTrend> t = time_trend(c, {&f});
    ASSERT_EQ(t.size(), 1u) << c;
    EXPECT_EQ(t[0].channel, c);
    EXPECT_GE(t[0].share, kTimeTrendShare) << c;
    std::printf("  %s: %.5f\n", c, t[0].share);
  }
  for (const char* c : {"cur_strb", "cur_heat", "cur_flap", "cur_acpwr", "cur_srvo_m", "ins_vn"}) {
    EXPECT_TRUE(time_trend(c, {&f}).empty()) << c;
    std::printf("  %s: %.5f\n", c, time_trend_share(Eigen::VectorXd(f.column(c)), f.dt_s()));
  }
  EXPECT_TRUE(time_trend("no_such_channel", {&f}).empty());
  // The note names the channel and what tells.
  TermSupport support;
  support.term = "scalar:cur_bat_2|lp(629)";
  support.time_trends = time_trend("cur_bat_2", {&f});
  const std::string note = time_trend_note(support);
  std::printf("  note: %s\n", note.c_str());
  EXPECT_NE(note.find("cur_bat_2 follows a smooth curve of time"), std::string::npos);
  EXPECT_NE(note.find("another course"), std::string::npos);
  support.time_trends.clear();
  EXPECT_EQ(time_trend_note(support), "");
}

TEST(TimeTrend, ATermOnAChannelThatFollowsTimeSaysSoInItsSupport) {
  // The closed-form TL flight with a current of 3 nT/A added to the scalar: a charge curve
  // 2 exp(-i / 2000) A, or a load switched every 500 samples. The model with the current's term
  // is fitted against the reference on every row; its support names the charge curve only.
  for (const bool charge : {true, false}) {
    Model start = test::tl16_model();
    start.fit.method = FitMethod::kReference;
    start.fit.reference = "mag_1_c";
    start.fit.lines.clear();
    FlightData f = test::synthetic_tl_flight(start, test::known_coefficients(16));
    Eigen::VectorXd x(f.size());
    for (Eigen::Index i = 0; i < x.size(); ++i)
      x[i] = charge ? 2.0 * std::exp(-static_cast<double>(i) / 2000.0) : (i / 500) % 2 ? 2.0 : 0.0;
    f.set("cur_x", x);
    f.mutable_column("mag_5_uc") += 3.0 * x;
    fit_model(start, {&f});
    Model m = start;
    m.add_term("scalar:cur_x");
    m.coefficients.resize(0);
    fit_model(m, {&f});
    const std::vector<TermSupport> s = term_support(m, start, f);
    ASSERT_EQ(s.size(), 1u);
    if (charge) {
      ASSERT_EQ(s[0].time_trends.size(), 1u);
      EXPECT_EQ(s[0].time_trends[0].channel, "cur_x");
      EXPECT_GE(s[0].time_trends[0].share, kTimeTrendShare);
      EXPECT_NE(time_trend_note(s[0]).find("cur_x follows"), std::string::npos);
    } else {
      EXPECT_TRUE(s[0].time_trends.empty());
      EXPECT_EQ(time_trend_note(s[0]), "");
    }
  }
}

// The benchmark's "named up to time trends": channels that follow the flight's time (among the
// named and the effects') are one class, so a battery's term in place of another battery's
// drift names it; a channel that does not follow time in an effect's place, or a class more,
// does not.
TEST(TimeTrend, TheBenchmarkCountsAChannelThatFollowsTimeInATrendsPlaceAsNamingIt) {
  test::DiscoveryRun d;
  d.true_channels = {"vol_bat_1", "cur_srvo_i"};
  d.named_channels = {"cur_bat_2", "cur_srvo_i"};
  EXPECT_FALSE(d.names_truth_up_to_time_trends());
  d.true_time_trends = {"vol_bat_1"};
  d.named_time_trends = {"cur_bat_2"};
  EXPECT_TRUE(d.names_truth_up_to_time_trends());
  d.named_channels = {"cur_bat_2", "vol_bat_2", "cur_srvo_i"};  // two of them: one class
  d.named_time_trends = {"cur_bat_2", "vol_bat_2"};
  EXPECT_TRUE(d.names_truth_up_to_time_trends());
  d.named_channels = {"cur_bat_2", "cur_srvo_i", "cur_strb"};  // a channel more
  d.named_time_trends = {"cur_bat_2"};
  EXPECT_FALSE(d.names_truth_up_to_time_trends());
  d.true_time_trends.clear();  // the drift's channel does not follow time: a battery is no name
  d.named_channels = {"cur_bat_2", "cur_srvo_i"};
  EXPECT_FALSE(d.names_truth_up_to_time_trends());
}

}  // namespace
}  // namespace magcomp
