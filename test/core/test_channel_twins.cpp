// channel_twins: which recorded channels no flight tells apart, on closed-form columns and on the
// simulator's electrical system.
#include <gtest/gtest.h>

#include <cmath>
#include <random>

#include "discovery_run.h"
#include "magcomp/core/diagnose/channel_twins.h"
#include "magcomp/core/math/correlation.h"
#include "scenario_cache.h"

namespace magcomp {
namespace {

// A 10 Hz flight of n rows: cur_a a slow random walk (A); cur_b 0.9 cur_a plus white noise of
// 0.3 A (a twin once smoothed over 5 s); cur_c cur_a plus a slow walk of its own (not a twin);
// ins_lat equal to cur_a (a position: never a twin).
FlightData closed_form_flight(Eigen::Index n, unsigned seed, bool b_follows_a = true) {
  std::mt19937_64 rng(seed);
  std::normal_distribution<double> normal(0.0, 1.0);
  Eigen::VectorXd tt(n), a(n), b(n), c(n), own(n), other(n);
  double walk = 10, slow = 0, free_walk = 5;
  for (Eigen::Index i = 0; i < n; ++i) {
    tt[i] = 0.1 * static_cast<double>(i);
    walk += 0.05 * normal(rng);
    slow += 0.02 * normal(rng);
    free_walk += 0.05 * normal(rng);
    a[i] = walk;
    own[i] = slow;
    other[i] = free_walk;
  }
  for (Eigen::Index i = 0; i < n; ++i) {
    b[i] = (b_follows_a ? 0.9 * a[i] : other[i]) + 0.3 * normal(rng);
    c[i] = a[i] + own[i];
  }
  FlightData f;
  f.set("tt", tt);
  f.set("cur_a", a);
  f.set("cur_b", b);
  f.set("cur_c", c);
  f.set("ins_lat", a);
  return f;
}

TEST(ChannelTwins, AChannelAndItsNoisyMultipleAreTwinsAChannelWithASlowPartOfItsOwnIsNot) {
  const FlightData f = closed_form_flight(20000, 1);
  const std::vector<ChannelTwin> twins = channel_twins("cur_a", {&f});
  ASSERT_EQ(twins.size(), 1u);
  EXPECT_EQ(twins[0].channel, "cur_a");
  EXPECT_EQ(twins[0].twin, "cur_b");
  EXPECT_GE(twins[0].correlation, kTwinCorrelation);
  EXPECT_LE(twins[0].correlation, 1.0);
  // Unsmoothed, the 0.3 A noise alone sets them apart: the window is what makes them twins.
  const auto a = f.column("cur_a"), b = f.column("cur_b");
  EXPECT_LT(std::abs(pearson(a, b)), kTwinCorrelation);
  // Twins both ways; skipped channels are not candidates.
  ASSERT_EQ(channel_twins("cur_b", {&f}).size(), 1u);
  EXPECT_EQ(channel_twins("cur_b", {&f})[0].twin, "cur_a");
  EXPECT_TRUE(channel_twins("cur_a", {&f}, {"cur_b"}).empty());
  EXPECT_TRUE(channel_twins("cur_c", {&f}).empty());
  EXPECT_TRUE(channel_twins("cur_missing", {&f}).empty());
}

TEST(ChannelTwins, OneFlightThatTellsThemApartIsEnough) {
  const FlightData same = closed_form_flight(20000, 2), apart = closed_form_flight(20000, 3, false);
  EXPECT_EQ(channel_twins("cur_a", {&same}).size(), 1u);
  EXPECT_TRUE(channel_twins("cur_a", {&apart}).empty());
  EXPECT_TRUE(channel_twins("cur_a", {&same, &apart}).empty());
  EXPECT_TRUE(channel_twins("cur_a", {&apart, &same}).empty());
}

// The simulator writes the power bus's two voltage taps from one drift and sag (0.2 V apart, each
// with its own 0.02 V noise) and the second battery's current as 0.9 times the first's: twins. The
// block voltage follows half the drift only, without the sag: not a twin of the bus.
TEST(ChannelTwins, TheSimulatorsBusTapsAndBatteryCurrentsAreTwinsTheBlockVoltageIsNot) {
  sim::Scenario s = sim::load_scenario(test::source_dir() + "/config/scenarios/lag.yaml");
  s.aircraft_states = true;
  const sim::Simulation sim = sim::simulate(s, Igrf::installed());
  const FlightData& f = sim.flight;
  auto names = [](const std::vector<ChannelTwin>& twins) {
    std::vector<std::string> out;
    for (const ChannelTwin& t : twins) out.push_back(t.twin);
    return out;
  };
  const std::vector<std::string> bus = names(channel_twins("vol_acpwr", {&f}));
  EXPECT_NE(std::find(bus.begin(), bus.end(), "vol_outpwr"), bus.end());
  EXPECT_EQ(std::find(bus.begin(), bus.end(), "vol_block"), bus.end());
  const std::vector<std::string> bat = names(channel_twins("cur_bat_1", {&f}));
  EXPECT_NE(std::find(bat.begin(), bat.end(), "cur_bat_2"), bat.end());
  EXPECT_TRUE(channel_twins("cur_strb", {&f}).empty());
}

// The benchmark's "named up to twins": a twin in an effect's channel's place names it; a channel
// that is no twin, or a channel more, does not.
TEST(ChannelTwins, TheBenchmarkCountsATwinInTheEffectsPlaceAsNamingItAndNothingElse) {
  test::DiscoveryRun d;
  d.true_channels = {"cur_bat_2", "cur_strb"};
  d.named_channels = {"cur_bat_1", "cur_strb"};
  EXPECT_FALSE(d.names_truth());
  EXPECT_FALSE(d.names_truth_up_to_twins());
  d.twins = {{"cur_bat_1", {"cur_bat_2"}}, {"cur_bat_2", {"cur_bat_1"}}};
  EXPECT_TRUE(d.names_truth_up_to_twins());
  d.named_channels = {"cur_bat_1", "cur_bat_2", "cur_strb"};  // both taps: one class, named once
  EXPECT_TRUE(d.names_truth_up_to_twins());
  d.named_channels = {"cur_bat_1", "cur_strb", "vol_block"};  // a channel more
  EXPECT_FALSE(d.names_truth_up_to_twins());
  d.named_channels = {"cur_bat_1"};  // an effect unnamed
  EXPECT_FALSE(d.names_truth_up_to_twins());
}

}  // namespace
}  // namespace magcomp
