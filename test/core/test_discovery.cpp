// The discovery loop on hidden effects drawn at random (sim/random_effects): a fixed-seed subset
// of scripts/bench_discovery. Each run: the loop chooses and fits its model on one flight; on
// the aircraft's next flight it must never be worse than the TL it started from, never say
// "complete" above 1.5x the noise floor, and here (a thermal source, a lag, a slow drift) reach
// the oracle within 1.5x + 0.05 nT.
#include <gtest/gtest.h>

#include "discovery_run.h"
#include "test_util.h"

namespace magcomp {
namespace {

TEST(Discovery, RandomEffectsCarryToTheNextFlight) {
  const sim::Scenario base =
      sim::load_scenario(test::source_dir() + "/config/scenarios/random_base.yaml");
  const Model tl = load_model_yaml(test::source_dir() + "/config/models/tl_sim.yaml");
  for (unsigned r : {1u, 3u, 5u}) {
    const test::DiscoveryRun d = test::discovery_run(r, 1, base, tl);
    std::string kept;
    for (const auto& t : d.added) kept += " " + t;
    std::printf("  run %u: %s: next flight TL %.3f, loop %.3f, oracle %.3f nT; kept%s; %s\n", r,
                d.effects.c_str(), d.tl_next_nT, d.loop_next_nT, d.oracle_next_nT, kept.c_str(),
                d.verdict.substr(0, d.verdict.find(':')).c_str());
    EXPECT_TRUE(d.predictable) << r;
    EXPECT_FALSE(d.worse_than_tl()) << r;
    EXPECT_FALSE(d.complete_above_floor()) << r << ": " << d.verdict;
    EXPECT_TRUE(d.near_oracle()) << r;
    EXPECT_LT(d.loop_next_nT, d.tl_next_nT) << r;
  }
}

TEST(Discovery, ASlowHeaterIsSizedByTheSlowStageAndCarriesOver) {
  // Run 15: the fuel pump's current heats a part (|I| through a 171 s lag). On the calibration
  // maneuvers its band-pass content is noise: the loop adds it as a slow term (fitted against
  // mag_1_c on the same segments, unfiltered) and the next flight falls to the oracle's reach.
  const sim::Scenario base =
      sim::load_scenario(test::source_dir() + "/config/scenarios/random_base.yaml");
  const Model tl = load_model_yaml(test::source_dir() + "/config/models/tl_sim.yaml");
  const test::DiscoveryRun d = test::discovery_run(15, 1, base, tl);
  std::string kept, slow;
  for (const auto& t : d.added) kept += " " + t;
  for (const auto& t : d.slow_terms) slow += " " + t;
  std::printf("  run 15: %s: next flight TL %.3f, loop %.3f, oracle %.3f nT; kept%s; slow%s\n",
              d.effects.c_str(), d.tl_next_nT, d.loop_next_nT, d.oracle_next_nT, kept.c_str(),
              slow.c_str());
  ASSERT_FALSE(d.slow_terms.empty());
  EXPECT_NE(d.slow_terms.front().find("cur_tank|"), std::string::npos) << slow;
  EXPECT_TRUE(d.near_oracle());
  EXPECT_FALSE(d.worse_than_tl());
}

TEST(Discovery, RandomEffectsAreSizedAndListed) {
  // Each drawn effect's rms on mag_5_uc lands in the drawn range (0.3-3 nT, the pilot's
  // linear scaling), and the same seed draws the same effects.
  sim::Scenario base =
      sim::load_scenario(test::source_dir() + "/config/scenarios/random_base.yaml");
  base.aircraft_seed = 77;
  const auto effects = sim::random_effects(base, 9, 3, Igrf::installed());
  ASSERT_EQ(effects.size(), 3u);
  const auto again = sim::random_effects(base, 9, 3, Igrf::installed());
  for (size_t k = 0; k < 3; ++k) EXPECT_EQ(sim::describe(effects[k]), sim::describe(again[k]));
  sim::Scenario s = base;
  s.hidden = effects;
  const sim::Simulation sim = sim::simulate(s, Igrf::installed());
  for (size_t k = 0; k < effects.size(); ++k) {
    if (effects[k].type == "lag") continue;
    const Eigen::VectorXd c =
        sim.truth.column("mag_5_uc.hidden." + std::to_string(k) + "." + effects[k].type);
    const double sd = std::sqrt((c.array() - c.mean()).square().mean());
    std::printf("  %s: %.3f nT\n", sim::describe(effects[k]).c_str(), sd);
    EXPECT_GT(sd, 0.25) << sim::describe(effects[k]);
    EXPECT_LT(sd, 3.5) << sim::describe(effects[k]);
  }
}

}  // namespace
}  // namespace magcomp
