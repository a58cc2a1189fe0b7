// The discovery loop on hidden effects drawn at random (sim/random_effects): a fixed-seed subset
// of scripts/bench_discovery. Each run: the loop chooses and fits its model on one flight; on
// the aircraft's next flight it must never be worse than the TL it started from (unless TL plus
// the effects' own terms is worse than TL there too: then within 5 % of those terms), never say
// "complete" above 1.5x the noise floor, and here (a thermal source, a lag, a slow drift) reach
// the oracle within 1.5x + 0.05 nT.
#include <gtest/gtest.h>

#include <Eigen/QR>
#include <algorithm>
#include <cmath>
#include <cstdio>
#include <optional>
#include <set>

#include "../../src/core/diagnose/loop_round.h"
#include "../../src/core/diagnose/loop_steps.h"
#include "../../src/core/diagnose/search.h"
#include "discovery_run.h"
#include "magcomp/core/diagnose/diagnose.h"
#include "magcomp/core/evaluate/evaluation.h"
#include "magcomp/core/fit/parameter_fit.h"
#include "magcomp/core/model/term.h"
#include "test_util.h"

namespace magcomp {
namespace {

// Every term the backward pass removed was redundant: its leaving raised the held-out variance by
// less than a quarter of the accepted share (the loop's message gives both errors). Returns the
// number of removals.
int expect_removals_redundant(const test::DiscoveryRun& d) {
  const double accept = DiagnoseOptions{}.accept_fraction;
  int removals = 0;
  for (const LoopRound& lr : d.rounds)
    for (const auto& [term, why] : lr.removed) {
      ++removals;
      double with_nT = NAN, without_nT = NAN;
      const size_t at = why.find("held-out error ");
      if (at == std::string::npos ||
          std::sscanf(why.c_str() + at, "held-out error %lf -> %lf", &with_nT, &without_nT) != 2) {
        ADD_FAILURE() << "no errors in: " << why;
        continue;
      }
      std::printf("  removed %s: %.4f -> %.4f nT\n", term.c_str(), with_nT, without_nT);
      EXPECT_LE(without_nT, with_nT / std::sqrt(1.0 - 0.25 * accept) + 1e-4) << term << ": " << why;
    }
  return removals;
}

// Runs of random_base: each carries to the next flight within reach of the oracle.
void expect_random_effects_carry(const std::vector<unsigned>& runs) {
  const sim::Scenario base =
      sim::load_scenario(test::source_dir() + "/config/scenarios/random_base.yaml");
  const Model tl = load_model_yaml(test::source_dir() + "/config/models/tl_sim.yaml");
  for (unsigned r : runs) {
    const test::DiscoveryRun d = test::discovery_run(r, 1, base, tl);
    std::string kept;
    for (const auto& t : d.added) kept += " " + t;
    std::printf("  run %u: %s: next flight TL %.3f, loop %.3f, oracle %.3f nT; kept%s; %s\n", r,
                d.effects.c_str(), d.tl_next_nT, d.loop_next_nT, d.oracle_next_nT, kept.c_str(),
                d.verdict.substr(0, d.verdict.find(':')).c_str());
    EXPECT_TRUE(d.predictable) << r;
    expect_removals_redundant(d);
    EXPECT_FALSE(d.complete_above_floor()) << r << ": " << d.verdict;
    EXPECT_TRUE(d.near_oracle()) << r;
    if (d.true_terms_next_nT <= d.tl_next_nT + 0.005) {
      EXPECT_FALSE(d.worse_than_tl()) << r;
      EXPECT_LT(d.loop_next_nT, d.tl_next_nT) << r;
    } else {
      // TL plus the effects' own terms is itself worse than TL on the next flight (run 5: TL
      // fitted with a battery's drift in it carries over better than without, 0.236 against
      // 0.316 nT): no honest model of the effect stays within TL there. The loop is held to the
      // true terms instead.
      std::printf("  run %u: TL + the true terms %.3f nT, worse than TL\n", r,
                  d.true_terms_next_nT);
      EXPECT_LE(d.loop_next_nT, 1.05 * d.true_terms_next_nT + 0.01) << r;
    }
  }
}

TEST(Discovery, RandomEffectsCarryToTheNextFlight) { expect_random_effects_carry({1}); }

// The long tests (suites *Long) run in scripts/bench_long_tests, not in the test command.
TEST(DiscoveryLong, RandomEffectsCarryToTheNextFlight) { expect_random_effects_carry({3, 5}); }

TEST(DiscoveryLong, ATermLeavesOnlyWhenLaterTermsMakeItRedundant) {
  // Run 11, first aircraft: an inductive pickup of cur_bat_2, a heater of cur_heat (I² through
  // 366 s) and a 63 s drift of cur_srvo_i. The pickup is kept first; the heater's term then joins
  // it, and the pickup is still needed: without it the held-out error doubles. The backward pass
  // removes a term only when its leaving raises the held-out variance by less than a quarter of
  // the accepted share; a pass that weighed the share with the wrong sign removed the pickup
  // there (0.542 -> 1.137 nT) and the next round put it back.
  const sim::Scenario base =
      sim::load_scenario(test::source_dir() + "/config/scenarios/random_base.yaml");
  const Model tl = load_model_yaml(test::source_dir() + "/config/models/tl_sim.yaml");
  const test::DiscoveryRun d = test::discovery_run(11, 3, base, tl, {}, 0);
  std::string kept;
  for (const auto& t : d.added) kept += " " + t;
  std::printf("  run 11/0: %s: next flight TL %.3f, loop %.3f, oracle %.3f nT; kept%s\n",
              d.effects.c_str(), d.tl_next_nT, d.loop_next_nT, d.oracle_next_nT, kept.c_str());
  expect_removals_redundant(d);
  for (const char* channel : {"cur_bat_2", "cur_heat"})
    EXPECT_TRUE(d.named_channels.count(channel)) << channel << ":" << kept;
  for (size_t k = 1; k < d.added.size(); ++k)
    EXPECT_EQ(std::count(d.added.begin(), d.added.end(), d.added[k]), 1) << d.added[k];
  EXPECT_TRUE(d.near_oracle()) << d.loop_next_nT << " against " << d.oracle_next_nT;
}

TEST(DiscoveryLong, ASlowHeaterIsSizedByTheSlowStageAndCarriesOver) {
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

// Run 3 on its second draw of aircraft and flights: a 0.49 s lag, a 34 s drift of vol_bat_2 and
// a product of the roll rate with the bus current cur_outpwr (a look-alike of cur_acpwr), which
// stays near its level: most of the product is the rate times a constant, which the base's eddy
// columns span. Once the lag is in the model, the pair screen scores each product beside the
// base's columns (a partial regression, as the fit will): the product of the roll rate with the
// bus current is fitted and ranked first, in place of the plain rate (which explains 23 % of the
// selection lines and is not accepted). A screen of each product alone ranked that pair 375th
// (6 % of the residual) behind products of the attitude angles, so it was never fitted.
// With the product in the model, the drift lives in the long line's pieces: the selection half
// sits at 0.058 nT, where a 59 % share is 0.021 nT, under the resolution; a slow term is
// accepted by kQuietHalfShare of that half with the resolution gained over all held-out lines.
// Which channel it names is the look-alikes' question: on this flight the cabin temperature
// through 166 s ranks first, the battery channels through 8-53 s within 2 points.
TEST(DiscoveryLong, AProductTheBaseSpansIsScreenedAndADriftOnAQuietHalfIsAccepted) {
  std::vector<sim::HiddenEffect> effects;
  const sim::Scenario a = test::discovery_scenario(
      3, 3, sim::load_scenario(test::source_dir() + "/config/scenarios/random_base.yaml"), 1,
      &effects);
  double lag_s = 0;
  for (const auto& e : effects) {
    std::printf("  effect: %s\n", sim::describe(e).c_str());
    if (e.type == "lag") lag_s = e.lag_s;
  }
  ASSERT_GT(lag_s, 0.3);
  const sim::Simulation fa = sim::simulate(a, Igrf::installed());
  Model start = load_model_yaml(test::source_dir() + "/config/models/tl_sim.yaml");
  start.terms.push_back("lag:" + std::to_string(lag_s));
  fit_model(start, {&fa.flight});
  const Diagnosis dx = diagnose(start, fa.flight, "mag_1_c");
  ASSERT_FALSE(dx.candidates.empty());
  const Candidate& top = dx.candidates.front();
  std::printf("  top: %s (selection %.1f %%, confirmation %.1f %%)\n", top.term.text().c_str(),
              100 * top.explained_selection, 100 * top.explained_confirmation);
  EXPECT_TRUE(top.accepted);
  const std::string t = top.term.text();
  EXPECT_NE(t.find("roll_rate"), std::string::npos) << t;
  EXPECT_TRUE(
      t.find("*cur_outpwr") != std::string::npos || t.find("cur_outpwr*") != std::string::npos ||
      t.find("*cur_acpwr") != std::string::npos || t.find("cur_acpwr*") != std::string::npos)
      << t;
  EXPECT_GE(top.explained_fraction, 0.5);
  // The drift, with the product in the model.
  start.terms.push_back("field:roll_rate*cur_outpwr");
  fit_model(start, {&fa.flight});
  const Diagnosis next = diagnose(start, fa.flight, "mag_1_c");
  ASSERT_FALSE(next.candidates.empty());
  const Candidate& drift = next.candidates.front();
  const double selection_gain_nT =
      next.baseline_selection_std_nT * (1 - std::sqrt(1 - drift.explained_selection));
  std::printf(
      "  then: %s (selection %.1f %% of %.3f nT: %.3f nT; confirmation %.1f %% of %.3f nT)\n",
      drift.term.text().c_str(), 100 * drift.explained_selection, next.baseline_selection_std_nT,
      selection_gain_nT, 100 * drift.explained_confirmation, next.baseline_confirmation_std_nT);
  EXPECT_TRUE(drift.accepted);
  // A slow term (the slow stage's), of a channel that rises with the battery's drift on this
  // flight: vol_bat_2's look-alikes, or the cabin temperature vol_cabt through 166 s.
  EXPECT_TRUE(drift.slow) << drift.term.text();
  EXPECT_LT(selection_gain_nT, DiagnoseOptions{}.resolution_nT);
  EXPECT_GE(drift.explained_selection, 0.25);
  EXPECT_GE(next.baseline_std_nT - drift.std_after_nT, DiagnoseOptions{}.resolution_nT);
}

TEST(DiscoveryLong, AnEffectOfSomeLinesIsChosenOnTheLinesThatHoldIt) {
  // Run 8: a lag and cur_ac_lo*yaw_rate, a current switched on during a piece of one line. After
  // the lag, the product explains 12 % of the residual on the selection lines and 77 % on the
  // confirmation lines; the selection lines rank a look-alike of the bus currents first, which
  // does not carry over. Ranked first on the confirmation lines and confirmed on the selection
  // lines, the product takes its place: the next flight reaches TL plus the true terms.
  const sim::Scenario base =
      sim::load_scenario(test::source_dir() + "/config/scenarios/random_base.yaml");
  const Model tl = load_model_yaml(test::source_dir() + "/config/models/tl_sim.yaml");
  const test::DiscoveryRun d = test::discovery_run(8, 2, base, tl);
  std::string kept;
  for (const auto& t : d.added) kept += " " + t;
  std::printf(
      "  run 8: %s: next flight TL %.3f, loop %.3f, true terms %.3f, oracle %.3f nT; kept%s\n",
      d.effects.c_str(), d.tl_next_nT, d.loop_next_nT, d.true_terms_next_nT, d.oracle_next_nT,
      kept.c_str());
  EXPECT_NE(kept.find("cur_ac_lo"), std::string::npos) << kept;
  EXPECT_EQ(kept.find("cur_bat_2"), std::string::npos) << kept;
  EXPECT_TRUE(d.near_true_terms()) << d.loop_next_nT;
  EXPECT_FALSE(d.worse_than_tl());
}

// Run 3 (a lag) with the ridge as shipped or chosen every round (choose): the lag alone is kept.
void expect_ridge_leaves_no_stand_in(bool choose) {
  const sim::Scenario base =
      sim::load_scenario(test::source_dir() + "/config/scenarios/random_base.yaml");
  const Model tl = load_model_yaml(test::source_dir() + "/config/models/tl_sim.yaml");
  DiagnoseOptions options;
  options.choose_lambda = choose;
  const test::DiscoveryRun d = test::discovery_run(3, 1, base, tl, options);
  std::string kept;
  for (const auto& t : d.added) kept += " " + t;
  std::printf("  run 3%s: %s: next flight TL %.3f, loop %.3f, oracle %.3f nT; kept%s\n",
              choose ? " (choose_lambda)" : "", d.effects.c_str(), d.tl_next_nT, d.loop_next_nT,
              d.oracle_next_nT, kept.c_str());
  int lags = 0, ridges = 0;
  for (const auto& t : d.added) {
    if (t.rfind("fit.lambda ", 0) == 0) {
      ++ridges;
      continue;
    }
    if (t == "bias + norm" || t == "norm" || t == "second_order") continue;  // TL's own form
    EXPECT_EQ(t.rfind("lag:", 0), 0u) << kept;
    ++lags;
  }
  // TL written as the exact norm and fitted against the reference chooses its ridge strength
  // on the held-out lines too (its round's model change names it).
  for (const LoopRound& lr : d.rounds)
    if (lr.model_change.find("fit.lambda") != std::string::npos) ++ridges;
  EXPECT_EQ(lags, 1) << kept;
  EXPECT_GE(ridges, 1) << kept;
  EXPECT_TRUE(d.names_truth()) << kept;
  EXPECT_TRUE(d.near_oracle()) << d.loop_next_nT;
  EXPECT_LT(d.loop_next_nT, 0.2) << d.loop_next_nT;  // 0.430 nT: TL + the lag at 1e-4
}

TEST(DiscoveryLong, ARidgeChosenOnTheHeldOutLinesLeavesNoTermStandingInForIt) {
  // Run 3: a 0.491 s lag. With the shipped ridge (fit.lambda 1e-4) the loop would keep, beside
  // the lag, a slow term of a channel that carries no effect (field:vol_back_p|lp(665): 5 V times
  // the permanent term's columns), standing in for the ridge's bias on TL's permanent columns
  // (doc/validation.md). By default such a term, within the model's own span, gives way to the
  // ridge step (DiagnoseOptions::ridge_for_span_terms); with choose_lambda the strength is chosen
  // every round (DiscoveryLong); TL written as the exact norm chooses the strength of its
  // reference fit on the held-out lines as well. Either way the loop keeps the lag alone (beside
  // TL's own form), and the next flight reaches the oracle fitted at the same ridge strength.
  expect_ridge_leaves_no_stand_in(false);
}

TEST(Discovery, ATermWhoseSizeDoesNotHoldOnTheCalibrationRowsIsRefused) {
  // Run 12, third aircraft: a 77.5 s drift of vol_block that the first flight barely shows
  // (0.19 nT within lines). After the ridge step, field:cur_strb|lp(39.8) passes both held-out
  // halves (0.268 -> 0.233 nT), but its band-pass size raises the unfiltered error on the
  // calibration maneuvers it is fitted on from 0.053 to 0.238 nT, and on the next flight it
  // makes the model worse than TL (0.629 against 0.581 nT). Refused there, it is not kept.
  // TL as given (DiagnoseOptions::exact_norm off): with TL written as the exact norm and fitted
  // against the stinger first, the drift lies within the bias's span on the calibration rows
  // and no term of a channel follows (doc/validation.md).
  const sim::Scenario base =
      sim::load_scenario(test::source_dir() + "/config/scenarios/random_base.yaml");
  const Model tl = load_model_yaml(test::source_dir() + "/config/models/tl_sim.yaml");
  DiagnoseOptions tl_as_given;
  tl_as_given.exact_norm = false;
  const test::DiscoveryRun d = test::discovery_run(12, 1, base, tl, tl_as_given, 2);
  std::string kept, refused = d.stop_reason + "; ";
  for (const auto& t : d.added) kept += " " + t;
  for (const LoopRound& lr : d.rounds)
    for (const auto& [term, why] : lr.rejected)
      if (why.find("calibration rows") != std::string::npos) refused += term + ": " + why + "; ";
  std::printf("  run 12/2: %s: next flight TL %.3f, loop %.3f, oracle %.3f nT; kept%s\n  %s\n",
              d.effects.c_str(), d.tl_next_nT, d.loop_next_nT, d.oracle_next_nT, kept.c_str(),
              refused.c_str());
  EXPECT_NE(refused.find("cur_strb|lp(39.8): the error on the calibration rows"), std::string::npos)
      << refused;
  EXPECT_EQ(kept.find("cur_strb"), std::string::npos) << kept;
  EXPECT_FALSE(d.worse_than_tl()) << d.loop_next_nT << " against " << d.tl_next_nT;
  // The error is scored on each calibration segment with its mean removed: finite, and the
  // first round's refit of TL leaves it well below the held-out error (the band-pass fits those
  // rows).
  ASSERT_FALSE(d.rounds.empty());
  EXPECT_TRUE(std::isfinite(d.rounds.front().calibration_std_nT));
  EXPECT_LT(d.rounds.front().calibration_std_nT, d.rounds.front().heldout_std_nT);
}

TEST(DiscoveryLong, ADriftTheCalibrationBarelyShowsIsSizedOnTheLines) {
  // Run 6, first aircraft: a 408 s drift of the flap motor's current. Within a calibration
  // segment it barely moves: sized there (the slow stage on the calibration rows alone), no
  // term passes and the loop keeps TL, 3.69 nT on the next flight
  // (scripts/bench_discovery ... slow-on-calibration). Sized on the held-out lines too (each
  // half scored with the size fitted on the other half's lines), the drift's own term is kept
  // and the next flight falls to the oracle's reach. The model file lists the lines.
  const sim::Scenario base =
      sim::load_scenario(test::source_dir() + "/config/scenarios/random_base.yaml");
  const Model tl = load_model_yaml(test::source_dir() + "/config/models/tl_sim.yaml");
  const test::DiscoveryRun d = test::discovery_run(6, 1, base, tl, {}, 0);
  std::string kept, slow;
  for (const auto& t : d.added) kept += " " + t;
  for (const auto& t : d.slow_terms) slow += " " + t;
  std::printf("  run 6/0: %s: next flight TL %.3f, loop %.3f, oracle %.3f nT; kept%s; slow%s\n",
              d.effects.c_str(), d.tl_next_nT, d.loop_next_nT, d.oracle_next_nT, kept.c_str(),
              slow.c_str());
  ASSERT_EQ(d.slow_terms.size(), 1u) << slow;
  EXPECT_EQ(d.slow_terms.front().rfind("scalar:cur_flap|", 0), 0u) << slow;
  // The flight shows the drift (its own term lowers the flight's error well beyond the
  // resolution): a run the benchmark counts among those the first flight can name.
  EXPECT_TRUE(d.shows_every_effect);
  EXPECT_TRUE(d.near_oracle()) << d.loop_next_nT << " against " << d.oracle_next_nT;
  EXPECT_LT(d.loop_next_nT, 0.25 * d.tl_next_nT);
  bool on_lines = false;
  for (const LoopRound& lr : d.rounds) on_lines = on_lines || lr.slow_on_lines;
  EXPECT_TRUE(on_lines);
  EXPECT_FALSE(d.slow_lines.empty());
  // The last diagnosis (its verdict and floor) reads the final model's held-out error as the
  // loop scored it, the slow term cross-fitted by halves, not sized on the rows it is scored on.
  std::printf("  held-out error: last round %.4f nT, last diagnosis %.4f nT\n",
              d.rounds.back().heldout_std_nT, d.last_heldout_nT);
  EXPECT_NEAR(d.last_heldout_nT, d.rounds.back().heldout_std_nT,
              1e-3 * d.rounds.back().heldout_std_nT);
}

TEST(Discovery, ADriftThatMovesBetweenTheLinesIsChosenOnTheLinesThatShowIt) {
  // Run 52, first aircraft: a heater of the fuel pump's current (cur_tank, 141 s). Its field
  // moves with the pump's steps, which fall in the turns between the survey lines: the
  // confirmation lines (pieces of the turns) hold most of it, the selection lines little. Its
  // own term lowers the selection lines' error by a fifth of their variance, less than the
  // resolution there (0.134 nT of error); the selection lines accept no term. Sized by the slow
  // stage on the held-out lines too (cross-fitted, as the loop sizes slow terms when the
  // calibration rows alone keep nothing) and chosen on the confirmation lines (a gain of the
  // resolution there, the accepted share on the selection lines, the resolution on all held-out
  // lines), it is accepted; without that the loop keeps TL with its ridge, 0.400 nT on the next
  // flight against the oracle's 0.135 (scripts/bench_discovery 1 52 half-several).
  const sim::Scenario base =
      sim::load_scenario(test::source_dir() + "/config/scenarios/random_base.yaml");
  std::vector<sim::HiddenEffect> effects;
  const sim::Scenario a = test::discovery_scenario(52, 1, base, 0, &effects);
  ASSERT_EQ(effects.size(), 1u);
  ASSERT_EQ(effects.front().channel, "cur_tank");
  sim::Scenario b = a;
  b.seed = a.seed + 1;
  const sim::Simulation fa = sim::simulate(a, Igrf::installed());
  const sim::Simulation fb = sim::simulate(b, Igrf::installed());
  Model tl = load_model_yaml(test::source_dir() + "/config/models/tl_sim.yaml");
  tl.fit.lambda = 1e-6;  // the ridge the loop chooses first on this flight
  fit_model(tl, {&fa.flight});
  // Slow terms sized on the held-out lines too, as the loop sizes them when the calibration rows
  // alone keep nothing (each half scored with the size from the other half's lines).
  std::set<double> lines;
  const Eigen::VectorXd line = fa.flight.column("line");
  for (Eigen::Index i = 0; i < line.size(); ++i)
    if (std::find(tl.fit.lines.begin(), tl.fit.lines.end(), line[i]) == tl.fit.lines.end())
      lines.insert(line[i]);
  Model sized = tl;
  sized.fit.slow_lines.assign(lines.begin(), lines.end());
  const DiagnoseOptions o;
  const Diagnosis dx = diagnose(sized, fa.flight, "mag_1_c", o);
  ASSERT_FALSE(dx.candidates.empty());
  const Candidate& top = dx.candidates.front();
  std::printf(
      "  run 52/0: %s: held-out %.3f -> %.3f nT (selection %.3f nT, %.1f%%; "
      "confirmation %.3f nT, %.1f%%)%s\n",
      top.term.text().c_str(), dx.baseline_std_nT, top.std_after_nT, dx.baseline_selection_std_nT,
      100 * top.explained_selection, dx.baseline_confirmation_std_nT,
      100 * top.explained_confirmation,
      top.chosen_on_confirmation ? " [chosen on the confirmation lines]" : "");
  EXPECT_EQ(top.term.text().rfind("field:cur_tank|", 0), 0u) << top.term.text();
  EXPECT_TRUE(top.accepted);
  EXPECT_TRUE(top.chosen_on_confirmation);
  EXPECT_TRUE(top.slow);
  // The case this covers: on the selection lines the term gains the accepted share but less
  // than the resolution, and no other candidate is accepted there.
  const double sel_gain_nT =
      dx.baseline_selection_std_nT * (1 - std::sqrt(1 - top.explained_selection));
  EXPECT_GE(top.explained_selection, o.accept_fraction);
  EXPECT_LT(sel_gain_nT, o.resolution_nT);
  for (size_t k = 1; k < dx.candidates.size(); ++k)
    EXPECT_FALSE(dx.candidates[k].accepted) << dx.candidates[k].term.text();
  EXPECT_LT(top.std_after_nT, 0.75 * dx.baseline_std_nT);
  // Carried to the aircraft's next flight, the term takes most of what TL leaves.
  Model with = sized;
  with.coefficients.resize(0);
  loop_steps::add_candidate_term(top.term, top.slow, "mag_1_c", &with);
  fit_model(with, {&fa.flight});
  const double tl_next = evaluate_model(tl, fb.flight, "mag_1_c", false).std_nT;
  const double with_next = evaluate_model(with, fb.flight, "mag_1_c", false).std_nT;
  std::printf("  next flight: TL %.3f nT, with the term %.3f nT\n", tl_next, with_next);
  EXPECT_LT(with_next, 0.5 * tl_next);
}

TEST(Discovery, ARoundTriesOneTermOfEachChannel) {
  // Run 12, third aircraft (a 77.5 s drift of vol_block): after the ridge, three forms of the
  // strobe current's heater rank first, and each raises the error on the calibration rows four-
  // to fivefold; tried in rank order, they were the round's three tries and the loop kept TL,
  // 0.508 nT on the next flight against the oracle's 0.167 (scripts/bench_discovery 1 12
  // half-several draws=3). The tries take the best form of each set of channels: the next one is
  // a voltage's slow term, kept, 0.207 nT there.
  const auto e = [](const char* t) { return loop_steps::Eligible{TermSpec(t), false, 0.3, NAN}; };
  const std::vector<loop_steps::Eligible> eligible = {e("field:cur_strb|lp(39.8)"),
                                                      e("field:cur_strb|pow(2)|lp(39.9)|sat(5.32)"),
                                                      e("field:cur_strb|pow(2)|lp(39.9)"),
                                                      e("scalar:vol_acpwr|lp(173)|sat(80.5)"),
                                                      e("scalar:vol_acpwr|lp(173)"),
                                                      e("lag:0.3"),
                                                      e("lag:0.25"),
                                                      e("field:cur_strb*vol_acpwr")};
  EXPECT_EQ(loop_steps::single_tries(eligible), (std::vector<size_t>{0, 3, 5}));
  // A lag reads no channel: each is its own try; a product is its own set of channels.
  const std::vector<loop_steps::Eligible> lags = {
      e("lag:0.3"), e("lag:0.25"), e("field:cur_strb|lp(39.8)"), e("field:cur_strb*vol_acpwr")};
  EXPECT_EQ(loop_steps::single_tries(lags), (std::vector<size_t>{0, 1, 2}));
  const std::vector<loop_steps::Eligible> products = {e("field:cur_strb|lp(39.8)"),
                                                      e("field:cur_strb*vol_acpwr"),
                                                      e("field:vol_acpwr*cur_strb|lp(2)")};
  EXPECT_EQ(loop_steps::single_tries(products), (std::vector<size_t>{0, 1}));
  EXPECT_TRUE(loop_steps::single_tries({}).empty());
}

TEST(Discovery, ARefusalNamesTheFlightsOnceTheFlightsAreTheHalves) {
  // Until a term is judged with the flights as the halves, a refusal names the selection and
  // confirmation halves of the held-out lines; after it, flight f (from 1) is in half (f - 1) % 2.
  LoopResult r;
  r.rounds.resize(2);
  EXPECT_EQ(loop_steps::half_name(r, 3, 0), "the selection half");
  EXPECT_EQ(loop_steps::half_name(r, 3, 1), "the confirmation half");
  r.rounds[1].flight_halves = true;
  EXPECT_EQ(loop_steps::half_name(r, 2, 0), "the held-out lines of flight 1");
  EXPECT_EQ(loop_steps::half_name(r, 2, 1), "the held-out lines of flight 2");
  EXPECT_EQ(loop_steps::half_name(r, 3, 0), "the held-out lines of flights 1, 3");
  EXPECT_EQ(loop_steps::half_name(r, 3, 1), "the held-out lines of flight 2");
  EXPECT_EQ(loop_steps::half_name(r, 1, 1), "the confirmation half");  // one flight: its own lines
}

TEST(Discovery, ALagThatTakesAnotherLagsPlaceIsRecordedAsReplacingIt) {
  // A model has one lag (Model::add_term): a step that adds lag:0.272 where lag:0.349 is in
  // force takes its place, whatever the step names as replaced (an exchange names the term the
  // model was diagnosed without). The rounds say so, so that what they list in force is what
  // the model holds.
  const auto row = [](const char* added) {
    LoopRound lr;
    lr.added = added;
    return lr;
  };
  Model start;
  start.terms = {TermSpec("permanent")};
  std::vector<LoopRound> rounds = {row(""), row("lag:0.349"), row("field:ins_vn"), row("lag:0.272"),
                                   row("lag:0.28")};
  rounds[3].replaced.emplace_back("field:ins_vn", "the model without it, diagnosed again, takes");
  // The last row: the lag's value estimated again once the rounds are spent, which names the
  // old lag itself; nothing is added to it.
  rounds[4].replaced.emplace_back("lag:0.272", "its value estimated again");
  loop_steps::record_displaced_lags(start, &rounds);
  ASSERT_EQ(rounds[3].replaced.size(), 2u);
  EXPECT_EQ(rounds[3].replaced[1].first, "lag:0.349");
  EXPECT_NE(rounds[3].replaced[1].second.find("lag:0.272 in its place"), std::string::npos);
  EXPECT_EQ(rounds[4].replaced.size(), 1u);
  EXPECT_TRUE(rounds[1].replaced.empty());
  EXPECT_TRUE(rounds[2].replaced.empty());
  // A lag of the starting model is displaced the same way; a lag removed earlier is not.
  start.terms.push_back(TermSpec("lag:0.2"));
  std::vector<LoopRound> from_start = {row(""), row("lag:0.3"), row("current:cur_strb"),
                                       row("lag:0.31")};
  from_start[2].removed.emplace_back("lag:0.3", "made redundant by later terms");
  loop_steps::record_displaced_lags(start, &from_start);
  ASSERT_EQ(from_start[1].replaced.size(), 1u);
  EXPECT_EQ(from_start[1].replaced[0].first, "lag:0.2");
  EXPECT_TRUE(from_start[3].replaced.empty());
}

TEST(DiscoveryLong, ATermWithinTheModelsOwnSpanIsNeverAdded) {
  // Run 1, first aircraft: a heater of cur_outpwr (50.7 s) and a 751 s drift of cur_srvo_m.
  // The field of a bus voltage held near its level (vol_block, vol_acpwr: a few tens of mV std
  // over the flight) through a low-pass lies 99.999 % within TL's columns on the calibration
  // rows: its columns there are the permanent term's times the bus's level, so its size is the
  // ridge's split of that level, and the next flight's level is read through it. Judged as any
  // other (DiagnoseOptions::refuse_within_span_terms false, scripts/bench_discovery 1 1
  // half-several span-terms), it is added and takes the next flight from TL's 0.848 to
  // 1.066 nT. Here such a term is refused for that reason and never added. The loop keeps the
  // heater's own channel, writes TL as the exact norm, and writes the drift with the second
  // battery's voltage (scalar:vol_bat_2|lp(190)): on the first flight that term leaves 0.196 nT
  // held out, the drift's own scalar:cur_srvo_m|lp(751) 0.252 (magcomp calibrate on the run's
  // flights, MAGCOMP_DISCOVERY_DUMP), so one flight prefers the battery, which follows a smooth
  // curve of time there and carries any drift of that shape; the output says so of it
  // (time_trend_note), and a second flight of the aircraft removes it
  // (AValidationFlightKeepsOutAStandInThatDoesNotCarryOver). On the next flight the model is no
  // worse than TL (0.842 against 0.848 nT).
  const auto e = [](const char* t, double span) {
    Candidate c;
    c.term = TermSpec(t);
    c.accepted = true;
    c.explained_fraction = 0.3;
    c.base_span_share = span;
    return c;
  };
  Diagnosis dx;
  dx.candidates = {e("field:vol_block|lp(21.1)|sat(69.1)", 0.9999993),
                   e("scalar:cur_acpwr|lp(49.2)", NAN), e("field:vol_outpwr|lp(53.9)", 0.9987)};
  const auto terms = [](const std::vector<loop_steps::Eligible>& el) {
    std::string out;
    for (const auto& x : el) out += x.term.text() + " ";
    return out;
  };
  EXPECT_EQ(terms(loop_steps::eligible_candidates({dx}, 0.02)),
            "scalar:cur_acpwr|lp(49.2) field:vol_outpwr|lp(53.9) ");
  EXPECT_EQ(
      terms(loop_steps::eligible_candidates({dx}, 0.02, true)),
      "field:vol_block|lp(21.1)|sat(69.1) scalar:cur_acpwr|lp(49.2) field:vol_outpwr|lp(53.9) ");

  const sim::Scenario base =
      sim::load_scenario(test::source_dir() + "/config/scenarios/random_base.yaml");
  const Model tl = load_model_yaml(test::source_dir() + "/config/models/tl_sim.yaml");
  const test::DiscoveryRun d = test::discovery_run(1, 2, base, tl, {}, 0);
  std::string kept;
  for (const auto& t : d.added) kept += " " + t;
  std::set<std::string> within_span;  // the terms refused as lying within the model's span
  for (const LoopRound& lr : d.rounds)
    for (const auto& [term, why] : lr.rejected)
      if (why.find("lies within the model's own columns") != std::string::npos)
        within_span.insert(term);
  std::string refused;
  for (const auto& t : within_span) refused += " " + t;
  std::printf(
      "  run 1/0: next flight TL %.3f, loop %.3f, oracle %.3f nT; kept%s; refused within "
      "the span%s\n",
      d.tl_next_nT, d.loop_next_nT, d.oracle_next_nT, kept.c_str(), refused.c_str());
  EXPECT_FALSE(within_span.empty());
  for (const LoopRound& lr : d.rounds) {
    EXPECT_EQ(within_span.count(lr.added), 0u) << lr.added;
    EXPECT_EQ(lr.added.find("vol_block"), std::string::npos) << lr.added;
  }
  // The heater's own channel or the bus current it follows (r 0.998 on this flight).
  EXPECT_TRUE(kept.find("cur_outpwr|lp(") != std::string::npos ||
              kept.find("cur_acpwr|lp(") != std::string::npos)
      << kept;
  // Every channel the final model reads beyond the effects' follows the flight's time: a
  // stand-in the output names as such, not a channel it claims.
  for (const std::string& c : d.named_channels) {
    if (!d.true_channels.count(c) && c != "cur_acpwr") {
      EXPECT_EQ(d.named_time_trends.count(c), 1u) << c;
    }
  }
  EXPECT_FALSE(d.worse_than_tl()) << d.loop_next_nT << " against " << d.tl_next_nT;
}

TEST(DiscoveryLong, AValidationFlightKeepsOutAStandInThatDoesNotCarryOver) {
  // Run 1, first aircraft: a heater of cur_outpwr (50.7 s) and a 751 s drift of cur_srvo_m.
  // Learned from its first flight alone with terms within the model's span judged as any other
  // once the ridge step is refused (scripts/bench_discovery 1 1 half-several span-terms
  // no-exchange), the loop's first term is a bus voltage held near 27.5 V through a low-pass and
  // a saturation, which follows both effects there and ends worse than TL on the next flight
  // (1.224 against 0.848 nT): the voltage's level on another flight is not where it was
  // fitted (ATermWithinTheModelsOwnSpanIsNeverAdded). With a second flight of the aircraft as the
  // validation flight (diagnose --apply
  // --validate), no step that raises that flight's error is kept, and the next flight falls well
  // below TL.
  const sim::Scenario base =
      sim::load_scenario(test::source_dir() + "/config/scenarios/random_base.yaml");
  const Model tl = load_model_yaml(test::source_dir() + "/config/models/tl_sim.yaml");
  DiagnoseOptions span_terms;
  span_terms.refuse_within_span_terms = false;
  const test::DiscoveryRun d =
      test::discovery_run(1, 2, base, tl, span_terms, 0, test::Learn::kValidated);
  std::string kept;
  for (const auto& t : d.added) kept += " " + t;
  std::printf("  run 1/0 validated: next flight TL %.3f, loop %.3f, oracle %.3f nT; kept%s\n",
              d.tl_next_nT, d.loop_next_nT, d.oracle_next_nT, kept.c_str());
  EXPECT_LT(d.loop_next_nT, 0.75 * d.tl_next_nT);
  for (const auto& t : d.added) EXPECT_EQ(t.find("vol_outpwr"), std::string::npos) << t;
}

TEST(DiscoveryLong, ATermChosenBeforeTheOtherEffectsWereWrittenGivesWay) {
  // Run 7, first aircraft: a 459 s drift of vol_bat_1, a relay of cur_srvo_i and a hysteresis of
  // cur_ac_hi. With the relay and the hysteresis still in the residual, the first round takes
  // scalar:cur_bat_1|lp(1.39) (a battery look-alike through a short lag), then the relay and a
  // term of cur_ac_hi; no fourth term passes. Without the exchange the loop stops there, 0.382 nT
  // on the next flight against the oracle's 0.116 (scripts/bench_discovery 6 7 half-several
  // draws=3 no-exchange). The model without that first term, diagnosed again, ranks a slow term
  // of the batteries first (scalar:cur_bat_2|lp(629): the batteries follow the same smooth curve
  // of time on this flight, so it writes the drift of vol_bat_1 there as well), which lowers the
  // held-out error by far more than the accepted share; it takes the place, the loop goes on,
  // and the next flight reaches the oracle (0.136 nT against 0.116).
  const sim::Scenario base =
      sim::load_scenario(test::source_dir() + "/config/scenarios/random_base.yaml");
  const Model tl = load_model_yaml(test::source_dir() + "/config/models/tl_sim.yaml");
  const test::DiscoveryRun d = test::discovery_run(7, 3, base, tl, {}, 0);
  std::string kept;
  for (const auto& t : d.in_force) kept += " " + t;
  std::printf("  run 7/0: %s: next flight TL %.3f, loop %.3f, oracle %.3f nT; kept%s\n",
              d.effects.c_str(), d.tl_next_nT, d.loop_next_nT, d.oracle_next_nT, kept.c_str());
  const DiagnoseOptions defaults;
  int exchanges = 0;
  for (size_t k = 1; k < d.rounds.size(); ++k)
    for (const auto& [term, why] : d.rounds[k].replaced) {
      ++exchanges;
      std::printf("  round %d: %s in place of %s: %s\n", d.rounds[k].round,
                  d.rounds[k].added.c_str(), term.c_str(), why.c_str());
      double with_nT = NAN, now_nT = NAN;
      const size_t at = why.find("held-out error ");
      ASSERT_NE(at, std::string::npos) << why;
      ASSERT_EQ(std::sscanf(why.c_str() + at, "held-out error %lf -> %lf", &with_nT, &now_nT), 2);
      // It lowers the error of the model with the term by the accepted share and the resolution,
      // on both halves, and the round's scores are that model's.
      EXPECT_LE(now_nT, with_nT * std::sqrt(1.0 - defaults.accept_fraction));
      EXPECT_LE(now_nT, with_nT - defaults.resolution_nT);
      EXPECT_NEAR(d.rounds[k].heldout_std_nT, now_nT, 1e-4);
      EXPECT_LE(d.rounds[k].selection_std_nT, d.rounds[k - 1].selection_std_nT);
      EXPECT_LE(d.rounds[k].confirmation_std_nT, d.rounds[k - 1].confirmation_std_nT);
      EXPECT_EQ((kept + " ").find(" " + term + " "), std::string::npos) << term << " kept:" << kept;
    }
  EXPECT_GE(exchanges, 1);
  // The drift's own channel, or a channel that follows the same smooth curve of time as
  // vol_bat_1 on this flight (a battery: time_trend), which writes the drift there as well and
  // which the output says this flight cannot name.
  ASSERT_EQ(d.true_time_trends.count("vol_bat_1"), 1u);
  bool drift_written = kept.find("vol_bat_1") != std::string::npos;
  for (const std::string& c : d.named_time_trends)
    drift_written = drift_written || !d.true_channels.count(c);
  EXPECT_TRUE(drift_written) << kept;
  EXPECT_TRUE(d.near_oracle()) << d.loop_next_nT << " against " << d.oracle_next_nT;
  EXPECT_FALSE(d.worse_than_tl());
}

// The held-out lines of `flight` as diagnose splits them: every line `model`'s fit does not
// read, each contiguous piece of a line a unit, the units dealt in time order into two halves.
std::vector<loop_steps::HeldOut> held_out_as_diagnose_splits(const FlightData& flight,
                                                             const Model& model) {
  std::vector<loop_steps::HeldOut> held(1);
  const Eigen::VectorXd line = flight.column("line");
  held[0].line = line;
  held[0].fold.assign(static_cast<size_t>(line.size()), -1);
  int units = 0;
  const auto& fit_lines = model.fit.lines;
  for (Eigen::Index i = 0, prev = -2; i < line.size(); ++i) {
    if (std::find(fit_lines.begin(), fit_lines.end(), line[i]) != fit_lines.end()) continue;
    if (prev != i - 1 || line[i] != line[prev]) ++units;
    held[0].fold[static_cast<size_t>(i)] = static_cast<signed char>((units - 1) % 2);
    prev = i;
  }
  EXPECT_GE(units, 4);
  return held;
}

// A round at a loop's end, built directly: run r's first and next flights on aircraft draw d
// (states recorded), the TL start fitted at `lambda`, the model with `terms` added and fitted,
// scored on the held-out lines as diagnose splits them.
// The TL template's ridge strength.
double base_lambda() {
  return load_model_yaml(test::source_dir() + "/config/models/tl_sim.yaml").fit.lambda;
}

// The first of a run's drawn effects of `type` on `channel` (any channel when empty); nullptr
// when the run draws none.
const sim::HiddenEffect* drawn(const std::vector<sim::HiddenEffect>& effects,
                               const std::string& type, const std::string& channel = "") {
  for (const auto& e : effects)
    if (e.type == type && (channel.empty() || e.channel == channel)) return &e;
  return nullptr;
}

// The benchmark's base flight with the aircraft's states recorded (scripts/bench_discovery …
// states): flaps, engine speed, outside air temperature, a heater switch.
sim::Scenario base_with_states() {
  sim::Scenario base =
      sim::load_scenario(test::source_dir() + "/config/scenarios/random_base.yaml");
  base.aircraft_states = true;
  return base;
}

struct RoundAtTheEnd {
  RoundAtTheEnd(const sim::Scenario& a, double lambda, const std::vector<std::string>& terms)
      : fa(sim::simulate(a, Igrf::installed())), fb(sim::simulate(next_of(a), Igrf::installed())) {
    start = load_model_yaml(test::source_dir() + "/config/models/tl_sim.yaml");
    start.fit.lambda = lambda;
    fit_model(start, {&fa.flight});
    model = start;
    for (const std::string& t : terms) model.add_term(TermSpec(t));
    fit_model(model, {&fa.flight});
    held = held_out_as_diagnose_splits(fa.flight, start);
    flights = {&fa.flight};
    r.model = model;
    r.rounds.push_back(loop_steps::score(model, flights, "mag_1_c", held, nullptr));
  }
  // The loop's state with `term` added as a slow term, fitted, and scored as its last round.
  LoopResult with_slow_term(const std::string& term) const {
    LoopResult out = r;
    loop_steps::add_candidate_term(TermSpec(term), true, truth, &out.model);
    fit_model(out.model, flights);
    out.rounds.push_back(loop_steps::score(out.model, flights, truth, held, nullptr));
    return out;
  }
  // The start model with TL written as the exact norm (fit.method reference against the truth,
  // fit.lambda 1e-6, as exact_norm_step writes it) and `terms` added, fitted on the first flight.
  Model exact_norm_with(const std::vector<std::string>& terms) const {
    Model m = start;
    m.fit.method = FitMethod::kReference;
    m.fit.reference = truth;
    m.fit.lambda = 1e-6;
    for (const std::string& t : terms) m.add_term(TermSpec(t));
    m.coefficients.resize(0);
    fit_model(m, flights);
    return m;
  }
  // The options a round of the loop diagnoses with (slow terms sized on the calibration rows).
  DiagnoseOptions round_options() const {
    DiagnoseOptions o = options;
    o.slow_terms_on_lines = false;
    return o;
  }
  // The candidates a round may add to the loop's model, in rank order: its diagnosis on the
  // first flight with round_options(), eligible as the loop takes them (min_share 0.05).
  std::vector<loop_steps::Eligible> round_candidates() const {
    return loop_steps::eligible_candidates({diagnose(r.model, *flights[0], truth, round_options())},
                                           0.05, false);
  }
  // The std of `m`'s error on the aircraft's next flight, nT.
  double next_nT(const Model& m) const {
    return evaluate_model(m, fb.flight, "mag_1_c", false).std_nT;
  }
  static sim::Scenario next_of(sim::Scenario a) {
    a.seed += 1;
    return a;
  }
  const sim::Simulation fa, fb;
  Model start, model;
  std::vector<loop_steps::HeldOut> held;
  std::vector<const FlightData*> flights;
  const DiagnoseOptions options;
  LoopResult r;
  const std::string truth = "mag_1_c";
  const loop_steps::LoopContext context{start, flights, truth, held, nullptr, options, 0.05};
};

TEST(Discovery, AnExchangeGivesAFirstTermsPlaceToWhatTheModelWithoutItRanksFirst) {
  // Run 7, first aircraft: a 459 s drift of vol_bat_1, a relay of cur_srvo_i and a hysteresis of
  // cur_ac_hi. The loop's first round takes scalar:cur_bat_1|lp(1.39) (a battery look-alike
  // through a short lag) while the relay and the hysteresis are still in the residual, then the
  // relay and a term of cur_ac_hi, and no fourth term passes (the model here, built directly;
  // DiscoveryLong.ATermChosenBefore... runs the loop to the next flight). The exchange takes the
  // first term out, diagnoses the model without it as the loop diagnoses a round, and the
  // drift's own channel takes its place: 0.3786 -> 0.2712 nT held out with
  // scalar:vol_bat_1|lp(12.6) (in the loop, whose relay threshold is not rounded, 0.3767 ->
  // 0.2647 nT with lp(11.3)).
  const sim::Scenario base =
      sim::load_scenario(test::source_dir() + "/config/scenarios/random_base.yaml");
  std::vector<sim::HiddenEffect> effects;
  const sim::Scenario a = test::discovery_scenario(7, 3, base, 0, &effects);
  const std::vector<std::string> kept = {
      "scalar:cur_bat_1|lp(1.39)", "field:cur_srvo_i|step(0.312)", "scalar:cur_ac_hi|lp(0.2)"};
  RoundAtTheEnd end(a, base_lambda(), kept);
  LoopResult& r = end.r;
  // The rounds that added them, one each, the last one scored as the model stands.
  const LoopRound now = r.rounds.back();
  r.rounds.assign(1, loop_steps::score(end.start, end.flights, end.truth, end.held, nullptr));
  for (size_t k = 0; k < kept.size(); ++k) {
    LoopRound lr = k + 1 == kept.size() ? now : r.rounds.back();
    lr.round = static_cast<int>(k) + 1;
    lr.added = kept[k];
    r.rounds.push_back(lr);
  }
  loop_steps::Round round(end.context, 4, &r);
  std::set<std::string> taken_out;
  std::printf("  kept: held out %.4f nT (halves %.4f, %.4f)\n", now.heldout_std_nT,
              now.selection_std_nT, now.confirmation_std_nT);
  const DiagnoseOptions round_options = end.round_options();
  ASSERT_TRUE(round.exchange(round_options, &taken_out));
  const LoopRound& after = r.rounds.back();
  ASSERT_EQ(after.replaced.size(), 1u);
  std::printf(
      "  held out %.4f nT (halves %.4f, %.4f); %s in place of %s: %.4f nT (halves %.4f, "
      "%.4f)\n",
      now.heldout_std_nT, now.selection_std_nT, now.confirmation_std_nT, after.added.c_str(),
      after.replaced[0].first.c_str(), after.heldout_std_nT, after.selection_std_nT,
      after.confirmation_std_nT);
  EXPECT_EQ(after.replaced[0].first, kept[0]);
  EXPECT_EQ(taken_out, std::set<std::string>{kept[0]});
  EXPECT_NE(after.added.find("vol_bat_1"), std::string::npos) << after.added;
  // It lowers the model's held-out error by the accepted share and the resolution, and neither
  // half rises.
  const DiagnoseOptions defaults;
  EXPECT_LE(after.heldout_std_nT, now.heldout_std_nT * std::sqrt(1.0 - defaults.accept_fraction));
  EXPECT_LE(after.heldout_std_nT, now.heldout_std_nT - defaults.resolution_nT);
  EXPECT_LE(after.selection_std_nT, now.selection_std_nT);
  EXPECT_LE(after.confirmation_std_nT, now.confirmation_std_nT);
  // The model is the kept terms without the first one, and the new term.
  std::vector<std::string> terms;
  for (const TermSpec& t : r.model.terms) terms.push_back(t.text());
  EXPECT_EQ(std::count(terms.begin(), terms.end(), kept[0]), 0);
  for (size_t k = 1; k < kept.size(); ++k)
    EXPECT_EQ(std::count(terms.begin(), terms.end(), kept[k]), 1) << kept[k];
}

TEST(Discovery, ATermChosenBeforeTheNormWasWrittenIsExchangedWithTheNormInPlace) {
  // Run 212, second aircraft, its states recorded: a 317 s drift of cur_bat_2. Under band-pass
  // TL the loop's first round takes scalar:vol_block|lp(665), a slow stand-in at the grid's
  // longest time constant (held out 0.345 nT), over the drift's own channel (0.368 nT, a
  // look-alike); the next round writes TL as the exact norm (0.133 nT), and no term passes after
  // it. The round that wrote the norm changed the model the stand-in was chosen beside, so the
  // exchange revisits it: with the norm in place, the drift's own channel takes its place
  // (0.017 nT held out). On the next flight the stand-in does worse than TL, 0.951 against
  // 0.688 nT, and the drift's channel leaves 0.016 nT (scripts/bench_discovery 1 212
  // half-several states draws=3).
  std::vector<sim::HiddenEffect> effects;
  const sim::Scenario a = test::discovery_scenario(212, 1, base_with_states(), 1, &effects);
  ASSERT_EQ(effects.size(), 1u);
  ASSERT_EQ(effects.front().type, "drift");
  ASSERT_EQ(effects.front().channel, "cur_bat_2");
  RoundAtTheEnd end(a, base_lambda(), {});
  const std::string stand_in = "scalar:vol_block|lp(665)";
  // Round 1: the stand-in, a slow term beside band-pass TL.
  LoopResult& r = end.r;
  r = end.with_slow_term(stand_in);
  r.rounds.back().round = 1;
  r.rounds.back().added = stand_in;
  // Round 2: TL as the exact norm, fitted against the reference (as exact_norm_step writes it).
  Model norm = r.model;
  norm.fit.method = FitMethod::kReference;
  norm.fit.reference = end.truth;
  norm.fit.lambda = 1e-6;
  norm.add_term(TermSpec("bias"));
  norm.add_term(TermSpec("norm"));
  norm.coefficients.resize(0);
  fit_model(norm, end.flights);
  LoopRound lr = loop_steps::score(norm, end.flights, end.truth, end.held, nullptr);
  lr.round = 2;
  lr.added = "bias + norm";
  lr.model_change = "TL as the exact norm; fit.method reference (mag_1_c), fit.lambda 1e-06";
  r.rounds.push_back(lr);
  r.model = norm;
  const LoopRound now = r.rounds.back();
  const DiagnoseOptions round_options = end.round_options();
  loop_steps::Round round(end.context, 2, &r);
  std::set<std::string> taken_out;
  ASSERT_TRUE(round.exchange(round_options, &taken_out));
  const LoopRound& after = r.rounds.back();
  ASSERT_EQ(after.replaced.size(), 1u);
  const double tl_next_nT = end.next_nT(end.start), stand_in_next_nT = end.next_nT(norm);
  const double next_nT = end.next_nT(r.model);
  std::printf(
      "  run 212/1: held out %.4f nT (halves %.4f, %.4f); %s in place of %s: %.4f nT (halves "
      "%.4f, %.4f); next flight TL %.3f nT, with the stand-in %.3f nT, after the exchange %.3f "
      "nT\n",
      now.heldout_std_nT, now.selection_std_nT, now.confirmation_std_nT, after.added.c_str(),
      after.replaced[0].first.c_str(), after.heldout_std_nT, after.selection_std_nT,
      after.confirmation_std_nT, tl_next_nT, stand_in_next_nT, next_nT);
  EXPECT_EQ(after.replaced[0].first, stand_in);
  EXPECT_NE(after.added.find("cur_bat_2"), std::string::npos) << after.added;
  EXPECT_LT(after.heldout_std_nT, 0.5 * now.heldout_std_nT);
  EXPECT_LE(after.selection_std_nT, now.selection_std_nT);
  EXPECT_LE(after.confirmation_std_nT, now.confirmation_std_nT);
  // The stand-in does worse than TL on the next flight; the drift's own channel carries over.
  EXPECT_GT(stand_in_next_nT, tl_next_nT);
  EXPECT_LT(next_nT, 0.25 * tl_next_nT);
}

TEST(Discovery, AnEddyDecayOfTheEarthsFieldIsExchangedForTheRateItStoodInFor) {
  // Run 269, first aircraft, its states recorded: a flex of the roll rate through 2.8 s and the
  // product yaw_rate*cur_heat. The body field's rate of change is the attitude's rates times the
  // field, so round 1 keeps field:B|decay(2.78), which reads no channel; TL is written as the
  // exact norm and the product follows, and no term passes. The decay was chosen before those
  // rounds: taken out, the model's diagnosis ranks the roll rate's own flex, which takes its
  // place: here 0.5241 -> 0.0108 nT held out, and 0.508 -> 0.011 nT on the next flight (in the
  // loop, whose rounds fit at their own ridge strengths, 0.6630 -> 0.1694 nT held out and 0.527
  // -> 0.153 nT on the next flight: scripts/bench_discovery 1 269 half-several states draws=3).
  std::vector<sim::HiddenEffect> effects;
  const sim::Scenario a = test::discovery_scenario(269, 2, base_with_states(), 0, &effects);
  ASSERT_EQ(effects.size(), 2u);
  ASSERT_EQ(effects[0].type, "flex");
  ASSERT_EQ(effects[0].channel, "roll_rate");
  ASSERT_EQ(effects[1].type, "product");
  RoundAtTheEnd end(a, base_lambda(), {});
  const std::string decay = "field:B|decay(2.78)", product = "field:yaw_rate*cur_heat";
  LoopResult& r = end.r;
  // Round 1: the decay beside band-pass TL.
  r.model.add_term(TermSpec(decay));
  r.model.coefficients.resize(0);
  fit_model(r.model, end.flights);
  LoopRound lr = loop_steps::score(r.model, end.flights, end.truth, end.held, nullptr);
  lr.round = 1;
  lr.added = decay;
  r.rounds.push_back(lr);
  // Round 2: TL as the exact norm (as exact_norm_step writes it), then the product.
  Model norm = end.exact_norm_with({decay, "bias", "norm"});
  lr = loop_steps::score(norm, end.flights, end.truth, end.held, nullptr);
  lr.round = 2;
  lr.added = "bias + norm";
  lr.model_change = "TL as the exact norm; fit.method reference (mag_1_c), fit.lambda 1e-06";
  r.rounds.push_back(lr);
  r.model = end.exact_norm_with({decay, "bias", "norm", product});
  lr = loop_steps::score(r.model, end.flights, end.truth, end.held, nullptr);
  lr.round = 2;
  lr.added = product;
  r.rounds.push_back(lr);
  const LoopRound now = r.rounds.back();
  const Model kept = r.model;
  loop_steps::Round round(end.context, 3, &r);
  std::set<std::string> taken_out;
  ASSERT_TRUE(round.exchange(end.round_options(), &taken_out));
  const LoopRound& after = r.rounds.back();
  ASSERT_EQ(after.replaced.size(), 1u);
  const double kept_next_nT = end.next_nT(kept), next_nT = end.next_nT(r.model);
  std::printf(
      "  run 269/0: held out %.4f nT (halves %.4f, %.4f); %s in place of %s: %.4f nT (halves "
      "%.4f, %.4f); next flight TL %.3f nT, with the decay %.3f nT, after the exchange %.3f nT\n",
      now.heldout_std_nT, now.selection_std_nT, now.confirmation_std_nT, after.added.c_str(),
      after.replaced[0].first.c_str(), after.heldout_std_nT, after.selection_std_nT,
      after.confirmation_std_nT, end.next_nT(end.start), kept_next_nT, next_nT);
  EXPECT_EQ(after.replaced[0].first, decay);
  EXPECT_EQ(after.added.rfind("field:roll_rate|lp(", 0), 0u) << after.added;
  EXPECT_LT(after.heldout_std_nT, 0.5 * now.heldout_std_nT);
  EXPECT_LE(after.selection_std_nT, now.selection_std_nT);
  EXPECT_LE(after.confirmation_std_nT, now.confirmation_std_nT);
  // The product and the norm stay; the next flight's error falls by half at least.
  std::vector<std::string> terms;
  for (const TermSpec& t : r.model.terms) terms.push_back(t.text());
  EXPECT_EQ(std::count(terms.begin(), terms.end(), decay), 0);
  EXPECT_EQ(std::count(terms.begin(), terms.end(), product), 1);
  EXPECT_EQ(std::count(terms.begin(), terms.end(), "norm"), 1);
  EXPECT_LT(next_nT, 0.5 * kept_next_nT);
}

TEST(Discovery, TheChannelThatPredictsWhatRemainsIsTriedWithTheModelFittedAgain) {
  // Run 251, first aircraft, its states recorded: a wire on cur_srvo_i, a 47.4 s heater of
  // cur_ac_hi and the product cur_bat_2*cur_srvo_o. The loop has kept the product, TL as the
  // exact norm (fit.lambda 1e-4) and the heater. What remains is predictable, and the flexible
  // model of all channels leans on cur_srvo_i first; but the search scores each candidate beside
  // TL's exact-norm column as the model's coefficients left it, and the servo current (0.3 A
  // plus twice the yaw rate's magnitude) moves with the maneuvers those coefficients were fitted
  // on: its terms rank far down there, below any share a round takes. Fitted with the whole
  // model, TL's remainder computed again, field:cur_srvo_i lowers the held-out error but raises
  // the selection half at the model's ridge strength; with the ridge weakened to 1e-7 (that
  // held TL's coefficients where the servo current had pulled them) both halves fall tenfold,
  // and so does the next flight's error.
  std::vector<sim::HiddenEffect> effects;
  const sim::Scenario a = test::discovery_scenario(251, 3, base_with_states(), 0, &effects);
  ASSERT_NE(drawn(effects, "wire", "cur_srvo_i"), nullptr);
  RoundAtTheEnd end(a, base_lambda(), {});
  LoopResult& r = end.r;
  Model m = end.start;
  m.fit.method = FitMethod::kReference;
  m.fit.reference = end.truth;
  m.fit.lambda = 1e-4;
  for (const char* t : {"field:cur_bat_2*cur_srvo_o", "bias", "norm", "field:cur_ac_hi|lp(48.8)"})
    m.add_term(TermSpec(t));
  m.coefficients.resize(0);
  fit_model(m, end.flights);
  r.model = m;
  LoopRound lr = loop_steps::score(m, end.flights, end.truth, end.held, nullptr);
  lr.round = 2;
  lr.added = "field:cur_ac_hi|lp(48.8)";
  r.rounds.push_back(lr);
  const LoopRound now = r.rounds.back();
  const std::vector<Diagnosis> dxs = {
      diagnose(r.model, *end.flights[0], end.truth, end.round_options())};
  ASSERT_FALSE(dxs[0].explainable.channels.empty());
  EXPECT_EQ(dxs[0].explainable.channels.front().first, "cur_srvo_i");
  // No eligible candidate of the round reads the servo current.
  for (const loop_steps::Eligible& e : loop_steps::eligible_candidates(dxs, 0.05, false))
    EXPECT_EQ(e.term.text().find("cur_srvo_i"), std::string::npos) << e.term.text();
  loop_steps::Round round(end.context, 3, &r);
  std::set<std::string> named;
  ASSERT_TRUE(round.named_channel_term(dxs, &named));
  const LoopRound& after = r.rounds.back();
  const double next_before_nT = end.next_nT(m), next_nT = end.next_nT(r.model);
  std::printf(
      "  run 251/0: held out %.4f nT (halves %.4f, %.4f); with %s (%s): %.4f nT (halves %.4f, "
      "%.4f); next flight %.3f -> %.3f nT\n",
      now.heldout_std_nT, now.selection_std_nT, now.confirmation_std_nT, after.added.c_str(),
      after.model_change.c_str(), after.heldout_std_nT, after.selection_std_nT,
      after.confirmation_std_nT, next_before_nT, next_nT);
  EXPECT_EQ(after.added, "field:cur_srvo_i");
  EXPECT_LT(r.model.fit.lambda, m.fit.lambda);
  EXPECT_NE(after.model_change.find("fit.lambda"), std::string::npos) << after.model_change;
  EXPECT_LT(after.heldout_std_nT, 0.1 * now.heldout_std_nT);
  EXPECT_LT(after.selection_std_nT, 0.1 * now.selection_std_nT);
  EXPECT_LT(after.confirmation_std_nT, 0.1 * now.confirmation_std_nT);
  EXPECT_LT(next_nT, 0.1 * next_before_nT);
  // Once per channel over the loop; and not at all when the option is off.
  EXPECT_FALSE(round.named_channel_term(dxs, &named));
  LoopResult again = end.r;
  again.model = m;
  again.rounds.pop_back();
  DiagnoseOptions off = end.options;
  off.named_channel_term = false;
  const loop_steps::LoopContext without{end.start, end.flights, end.truth, end.held,
                                        nullptr,   off,         0.05};
  loop_steps::Round plain_off(without, 3, &again);
  std::set<std::string> none;
  EXPECT_FALSE(plain_off.named_channel_term(dxs, &none));
  EXPECT_TRUE(none.empty());
}

// The loop's state with `term` added to `m` as a slow term, fitted on the first flight, and
// scored as its last round (`added`, round `round`).
void add_slow_round(const RoundAtTheEnd& end, const Model& m, const std::string& term, int round,
                    LoopResult* r) {
  r->model = m;
  loop_steps::add_candidate_term(TermSpec(term), true, end.truth, &r->model);
  r->model.coefficients.resize(0);
  fit_model(r->model, end.flights);
  LoopRound lr = loop_steps::score(r->model, end.flights, end.truth, end.held, nullptr);
  lr.round = round;
  lr.added = term;
  r->rounds.push_back(lr);
}

// `drift` taken out of the loop's model as Round::drop_chance_slow_term takes it out: the model
// without it fitted and scored, the removal said in the last round.
void take_out_as_chance(const RoundAtTheEnd& end, const std::string& drift, LoopResult* r) {
  Model without = loop_steps::without_term(r->model, TermSpec(drift));
  fit_model(without, end.flights);
  r->rounds.back().removed.emplace_back(drift, "a drift one flight cannot tell from chance");
  loop_steps::take_scores(loop_steps::score(without, end.flights, end.truth, end.held, nullptr),
                          &r->rounds.back());
  r->model = std::move(without);
}

// TL written as the exact norm on `m`, as exact_norm_step takes it: of loop_steps::
// exact_norm_forms, the one that, fitted on the flights, leaves the least held out (its fit's
// change in words second; "" when the fit stays). Nullopt when there is none.
std::optional<std::pair<Model, std::string>> best_exact_norm_form(const RoundAtTheEnd& end,
                                                                  const Model& m) {
  std::optional<std::pair<Model, std::string>> best;
  double best_nT = INFINITY;
  for (auto& form : loop_steps::exact_norm_forms(m, end.flights, end.truth)) {
    form.first.coefficients.resize(0);
    fit_model(form.first, end.flights);
    const double nT =
        loop_steps::score(form.first, end.flights, end.truth, end.held, nullptr).heldout_std_nT;
    if (nT < best_nT) {
      best_nT = nT;
      best = std::move(form);
    }
  }
  return best;
}

TEST(Discovery, TheChanceLevelReadsOnlyTheStatesTheModelDoesNotReadShiftedInTime) {
  // Ten samples: two states, one of them read by the model, and channels that are no state.
  FlightData data;
  Eigen::VectorXd ramp(10);
  for (Eigen::Index i = 0; i < ramp.size(); ++i) ramp[i] = static_cast<double>(i);
  for (const char* name : {"tt", "line", "mag_1_c", "mag_5_uc", "ins_vn", "cur_heat", "cur_bat_1"})
    data.set(name, ramp);
  Model model;
  model.add_term(TermSpec("current:cur_heat"));
  EXPECT_TRUE(loop_steps::shiftable_channel("cur_bat_1", model, "mag_1_c"));
  EXPECT_FALSE(loop_steps::shiftable_channel("cur_heat", model, "mag_1_c"));
  EXPECT_FALSE(loop_steps::shiftable_channel("ins_vn", model, "mag_1_c"));
  EXPECT_FALSE(loop_steps::shiftable_channel("mag_1_c", model, "mag_1_c"));
  EXPECT_TRUE(loop_steps::reads_shiftable_channels_only(TermSpec("scalar:cur_bat_1|lp(300)"), model,
                                                        "mag_1_c"));
  EXPECT_FALSE(loop_steps::reads_shiftable_channels_only(TermSpec("field:cur_bat_1*cur_heat"),
                                                         model, "mag_1_c"));
  // A quarter of ten samples rounds to three: sample i reads sample i - 3, circularly.
  const FlightData shifted = loop_steps::with_states_shifted(data, model, "mag_1_c", 0.25);
  for (Eigen::Index i = 0; i < 10; ++i) {
    EXPECT_EQ(shifted.column("cur_bat_1")[i], static_cast<double>((i + 7) % 10)) << i;
    for (const char* name : {"tt", "line", "mag_1_c", "mag_5_uc", "ins_vn", "cur_heat"})
      EXPECT_EQ(shifted.column(name)[i], static_cast<double>(i)) << name << " " << i;
  }
  // Beyond chance: what it leaves is at most what two chance terms leave in turn.
  loop_steps::ChanceLevel chance;
  chance.share = 0.8;
  EXPECT_TRUE(loop_steps::beyond_chance(0.97, chance));
  EXPECT_FALSE(loop_steps::beyond_chance(0.95, chance));
  chance.share = 0.0;
  EXPECT_TRUE(loop_steps::beyond_chance(0.02, chance));
  // Down to the resolution (0.03 nT): chance at 96 % of 0.5 nT leaves 0.1 nT.
  chance.share = 0.96;
  EXPECT_TRUE(loop_steps::beyond_chance_to_the_resolution(0.025, 0.5, chance, 0.03));
  EXPECT_FALSE(loop_steps::beyond_chance_to_the_resolution(0.035, 0.5, chance, 0.03));
  EXPECT_FALSE(loop_steps::beyond_chance_to_the_resolution(0.025, 0.25, chance, 0.03));
}

TEST(Discovery, ADriftOneFlightCannotTellFromChanceIsTakenOut) {
  // Run 218, second aircraft, its states recorded: a 310 s drift of the rail vol_back's white
  // noise, a slow random wander. Over the first flight the loop keeps scalar:vol_cabt|lp(35.1),
  // a cabin channel's trend that follows it (held out 1.099 -> 0.351 nT), and stops; on the
  // next flight that term leaves 0.964 nT against TL's 0.382. With every other term in place it
  // explains less than the search finds with the recorded states read shifted in time (a
  // quarter, a half, three quarters of the flight), by the margin: it is taken out, and the
  // model is TL again (scripts/bench_discovery 1 218 half-several states draws=3). Its pace is
  // the cabin trend's, not the 35 s low-pass's (correlation time 336 s): shifted terms of that
  // pace or faster explain 74 %, and it is taken out as well.
  std::vector<sim::HiddenEffect> effects;
  const sim::Scenario a = test::discovery_scenario(218, 1, base_with_states(), 1, &effects);
  ASSERT_EQ(effects.size(), 1u);
  ASSERT_EQ(effects.front().type, "drift");
  RoundAtTheEnd end(a, base_lambda(), {});
  const std::string stand_in = "scalar:vol_cabt|lp(35.1)";
  LoopResult& r = end.r;
  add_slow_round(end, end.start, stand_in, 1, &r);
  const Model with_stand_in = r.model;
  const LoopRound now = r.rounds.back();
  const DiagnoseOptions round_options = end.round_options();
  loop_steps::Round audit(end.context, 1, &r);
  std::set<std::string> audited;
  ASSERT_TRUE(audit.drop_chance_slow_term(round_options, &audited));
  const LoopRound& after = r.rounds.back();
  ASSERT_EQ(after.removed.size(), 1u);
  const double tl_next_nT = end.next_nT(end.start), stand_in_next_nT = end.next_nT(with_stand_in);
  std::printf(
      "  run 218/1: held out %.4f nT (halves %.4f, %.4f) with %s, %.4f without; next "
      "flight TL %.3f nT, with it %.3f nT\n  %s\n",
      now.heldout_std_nT, now.selection_std_nT, now.confirmation_std_nT, stand_in.c_str(),
      after.heldout_std_nT, tl_next_nT, stand_in_next_nT, after.removed[0].second.c_str());
  EXPECT_EQ(after.removed[0].first, stand_in);
  EXPECT_NE(after.removed[0].second.find("shifted in time"), std::string::npos);
  EXPECT_TRUE(std::find(r.model.terms.begin(), r.model.terms.end(), TermSpec(stand_in)) ==
              r.model.terms.end());
  // It gains on this flight's held-out lines, and does worse than TL on the next flight.
  EXPECT_LT(now.heldout_std_nT, 0.5 * after.heldout_std_nT);
  EXPECT_GT(stand_in_next_nT, 1.5 * tl_next_nT);
  EXPECT_NEAR(end.next_nT(r.model), tl_next_nT, 1e-3);
  // Taken in alone and last, it leaves nothing to judge again.
  EXPECT_EQ(audit.shed_after_chance_drift(stand_in), 0);
  EXPECT_EQ(r.rounds.back().removed.size(), 1u);
  // Tried once: a second call finds nothing more to take out.
  loop_steps::Round again(end.context, 1, &r);
  EXPECT_FALSE(again.drop_chance_slow_term(round_options, &audited));
}

TEST(Discovery, WhatARoundTookInWithADriftTakenOutAsChanceIsJudgedAgain) {
  // Run 159, first aircraft, its states recorded: a 43.7 s thermal of cur_flap, a product
  // cur_bat_2*cur_srvo_i and an inductive pick-up of cur_heat. After three rounds (the thermal,
  // the pick-up, a stand-in of the product) the loop takes TL's exact norm in together with
  // field:cur_strb|lp(112), a trend of a channel that carries no effect (0.336 -> 0.190 nT held
  // out). The chance control takes the trend out; the norm, fitted against the reference with
  // the trend in place, stays without it at 1.054 nT held out, three times the model before the
  // round, and 0.908 nT on the next flight. Judged again without the trend, the norm leaves too,
  // and the next flight is 0.319 nT (scripts/bench_discovery 1 159 half-several states
  // draws=1). Here the round is built directly and the trend taken out as the audit takes it:
  // 0.394 nT held out before the round, 0.339 with it, 0.938 without the trend; on the next
  // flight 0.954 nT with the norm left alone, 0.324 once it leaves too.
  std::vector<sim::HiddenEffect> effects;
  const sim::Scenario a = test::discovery_scenario(159, 3, base_with_states(), 0, &effects);
  ASSERT_EQ(effects.size(), 3u);
  RoundAtTheEnd end(a, base_lambda(), {"dcurrent:cur_heat", "field:cur_srvo_i|lp(0.2)"});
  LoopResult& r = end.r;
  add_slow_round(end, r.model, "field:cur_flap|lp(45.5)", 1, &r);
  const Model before = r.model;
  const LoopRound before_round = r.rounds.back();
  // The round: each form of the exact norm with the trend, the lowest held-out error kept.
  const std::string trend = "field:cur_strb|lp(112)";
  std::optional<Model> with_norm;
  double with_norm_nT = INFINITY;
  for (auto& [m, change] : loop_steps::exact_norm_forms(before, end.flights, end.truth)) {
    if (change.empty()) continue;  // the fit against the reference, as the loop took it
    LoopResult probe = r;
    add_slow_round(end, m, trend, 2, &probe);
    if (probe.rounds.back().heldout_std_nT < with_norm_nT) {
      with_norm_nT = probe.rounds.back().heldout_std_nT;
      with_norm = probe.model;
    }
  }
  ASSERT_TRUE(with_norm.has_value());
  add_slow_round(end, *with_norm, trend, 2, &r);
  r.rounds.back().added = "bias + norm + " + trend;
  r.rounds.back().together = true;
  const Model with_trend = r.model;
  // The trend taken out as the chance control takes it out (Round::drop_chance_slow_term; its
  // decision is the subject of the tests around this one): the model without it, fitted and
  // scored, the removal said in the last round.
  take_out_as_chance(end, trend, &r);
  loop_steps::Round audit(end.context, 1, &r);
  const Model without_trend = r.model;
  const double without_trend_nT = r.rounds.back().heldout_std_nT;
  EXPECT_EQ(audit.shed_after_chance_drift(trend), 1);
  const LoopRound& after = r.rounds.back();
  ASSERT_EQ(after.removed.size(), 2u);
  std::printf(
      "  run 159/0: held out %.4f nT before the round, %.4f with the norm and %s, %.4f without "
      "the trend, %.4f without the norm too\n  %s\n",
      before_round.heldout_std_nT, with_norm_nT, trend.c_str(), without_trend_nT,
      after.heldout_std_nT, after.removed[1].second.c_str());
  EXPECT_EQ(after.removed[1].first, "bias + norm");
  EXPECT_NE(after.removed[1].second.find("taken in together with " + trend), std::string::npos);
  // The model is the one before the round: its terms, its fit, its held-out error.
  EXPECT_EQ(r.model.terms, before.terms);
  EXPECT_EQ(r.model.fit.method, before.fit.method);
  EXPECT_DOUBLE_EQ(r.model.fit.lambda, before.fit.lambda);
  EXPECT_NEAR(after.heldout_std_nT, before_round.heldout_std_nT, 1e-9);
  // Without the trend the norm did worse than the model before the round, by a factor 2 or more.
  EXPECT_GT(without_trend_nT, 2 * before_round.heldout_std_nT);
  const double next_without_trend_nT = end.next_nT(without_trend), next_nT = end.next_nT(r.model);
  std::printf(
      "  next flight: %.3f nT with the norm and no trend, %.3f nT without either; TL %.3f "
      "nT, the model with the trend %.3f nT\n",
      next_without_trend_nT, next_nT, end.next_nT(end.start), end.next_nT(with_trend));
  EXPECT_LT(next_nT, 0.5 * next_without_trend_nT);
  // Nothing more leaves: a second call finds the model as before the round.
  EXPECT_EQ(audit.shed_after_chance_drift(trend), 0);
}

TEST(Discovery, TheExactNormTakenInAfterADriftTakenOutAsChanceIsJudgedAgain) {
  // Run 137, second aircraft, its states recorded: a relay of cur_outpwr and a 363 s drift of
  // cur_heat, both of which the first flight barely shows. The loop sets the ridge to 1e-6,
  // keeps the relay (0.213 nT held out) and the drift scalar:cur_heat|lp(365) (0.151), and then
  // writes TL as the exact norm (0.027). Taken out as chance by the second draw's margin alone
  // (99.8 % against chance's 96.9 %; the audit keeps it since it leaves nothing the search
  // resolves: ADriftThatLeavesNothingToResolve…), the norm, fitted with the drift in place,
  // leaves 0.658 nT held out without it, and 0.747 nT on the next flight against TL's 0.689:
  // worse than TL. Judged again without the drift, the norm leaves: 0.213 nT held out, 0.244 on
  // the next flight. Here the rounds are built directly, with the loop's numbers, and the drift
  // taken out as the audit takes a drift it cannot tell from chance.
  std::vector<sim::HiddenEffect> effects;
  const sim::Scenario a = test::discovery_scenario(137, 2, base_with_states(), 1, &effects);
  ASSERT_EQ(effects.size(), 2u);
  RoundAtTheEnd end(a, base_lambda(), {});
  LoopResult& r = end.r;
  const auto push_round = [&](const std::string& added) {
    r.model.coefficients.resize(0);
    fit_model(r.model, end.flights);
    LoopRound lr = loop_steps::score(r.model, end.flights, end.truth, end.held, nullptr);
    lr.round = static_cast<int>(r.rounds.size());
    lr.added = added;
    r.rounds.push_back(lr);
  };
  r.model.fit.lambda = 1e-6;
  push_round("fit.lambda 1e-06");
  r.model.add_term(TermSpec("field:cur_outpwr|step(14.4804)"));
  push_round("field:cur_outpwr|step(14.4804)");
  const Model relay = r.model;
  const std::string drift = "scalar:cur_heat|lp(365)";
  add_slow_round(end, r.model, drift, 3, &r);
  // TL as the exact norm: the form that leaves the least held out, as exact_norm_step takes it.
  const std::optional<std::pair<Model, std::string>> norm = best_exact_norm_form(end, r.model);
  ASSERT_TRUE(norm.has_value());
  r.model = norm->first;
  push_round(norm->second.empty() ? "norm" : "bias + norm");
  take_out_as_chance(end, drift, &r);
  const Model without = r.model;
  const double without_drift_nT = r.rounds.back().heldout_std_nT;
  loop_steps::Round audit(end.context, 1, &r);
  EXPECT_GE(audit.shed_after_chance_drift(drift), 1);
  const LoopRound& after = r.rounds.back();
  ASSERT_GE(after.removed.size(), 2u);
  const double tl_next_nT = end.next_nT(end.start), left_next_nT = end.next_nT(without),
               next_nT = end.next_nT(r.model);
  std::printf(
      "  run 137/1: held out %.4f nT with the relay, %.4f with the drift and the norm, %.4f "
      "without the drift, %.4f once judged again\n  %s: %s\n  next flight: TL %.3f nT, the "
      "norm left without the drift %.3f nT, judged again %.3f nT\n",
      loop_steps::score(relay, end.flights, end.truth, end.held, nullptr).heldout_std_nT,
      loop_steps::score(norm->first, end.flights, end.truth, end.held, nullptr).heldout_std_nT,
      without_drift_nT, after.heldout_std_nT, after.removed[1].first.c_str(),
      after.removed[1].second.c_str(), tl_next_nT, left_next_nT, next_nT);
  EXPECT_NE(after.removed[1].first.find("norm"), std::string::npos);
  EXPECT_NE(after.removed[1].second.find("taken in after " + drift), std::string::npos);
  EXPECT_TRUE(std::find(r.model.terms.begin(), r.model.terms.end(), "norm") == r.model.terms.end());
  EXPECT_LT(after.heldout_std_nT, 0.75 * without_drift_nT);
  // The model left without the drift does worse than TL on the next flight; judged again, not.
  EXPECT_GT(left_next_nT, tl_next_nT);
  EXPECT_LT(next_nT, tl_next_nT);
}

TEST(Discovery, ADriftThatExplainsWhatRemainsBeyondChanceStays) {
  // Run 212, second aircraft, its states recorded: a 317 s drift of cur_bat_2. With TL written
  // as the exact norm, scalar:cur_bat_2|lp(332) leaves 0.017 nT held out, where the recorded
  // states read shifted in time explain a fraction of what it does: it stays, and carries to the
  // next flight (0.016 nT against TL's 0.688).
  std::vector<sim::HiddenEffect> effects;
  const sim::Scenario a = test::discovery_scenario(212, 1, base_with_states(), 1, &effects);
  ASSERT_EQ(effects.size(), 1u);
  ASSERT_EQ(effects.front().channel, "cur_bat_2");
  RoundAtTheEnd end(a, base_lambda(), {});
  const std::string drift = "scalar:cur_bat_2|lp(332)";
  LoopResult& r = end.r;
  Model norm = end.exact_norm_with({"bias", "norm"});
  add_slow_round(end, norm, drift, 1, &r);
  const DiagnoseOptions round_options = end.round_options();
  const LoopRound now = r.rounds.back();
  const size_t terms = r.model.terms.size();
  loop_steps::Round audit(end.context, 1, &r);
  std::set<std::string> audited;
  EXPECT_FALSE(audit.drop_chance_slow_term(round_options, &audited));
  EXPECT_EQ(audited.count(drift), 1u);
  EXPECT_EQ(r.model.terms.size(), terms);
  const double next_nT = end.next_nT(r.model), tl_next_nT = end.next_nT(end.start);
  std::printf("  run 212/1: held out %.4f nT with %s; next flight %.3f nT, TL %.3f nT\n",
              now.heldout_std_nT, drift.c_str(), next_nT, tl_next_nT);
  EXPECT_LT(next_nT, 0.25 * tl_next_nT);
}

TEST(DiscoveryLong, ADriftThatLeavesNothingToResolveIsBeyondAChanceThatLeavesMore) {
  // Run 137, second aircraft, its states recorded: a relay of cur_outpwr and a 363 s drift of
  // cur_heat. With the relay, the drift's own term scalar:cur_heat|lp(365) and TL as the exact
  // norm, 0.027 nT is left held out (the resolution: 0.03 nT); without the drift 0.658 nT. The
  // recorded states read shifted in time explain 96.9 % of that by one trend and leave 0.116 nT:
  // two such draws would leave 0.1 % (0.020 nT), less than the search resolves, and the second
  // draw's margin took the drift out. Compared down to the resolution, it stays, and the next
  // flight is a twentieth of TL's (scripts/bench_discovery 1 137 half-several states draws=3).
  std::vector<sim::HiddenEffect> effects;
  const sim::Scenario a = test::discovery_scenario(137, 2, base_with_states(), 1, &effects);
  ASSERT_EQ(effects.size(), 2u);
  RoundAtTheEnd end(a, base_lambda(), {});
  LoopResult& r = end.r;
  Model relay = end.start;
  relay.fit.lambda = 1e-6;
  relay.add_term(TermSpec("field:cur_outpwr|step(14.4804)"));
  const std::string drift = "scalar:cur_heat|lp(365)";
  // TL as the exact norm beside the drift: the form that leaves the least held out.
  Model with_drift = relay;
  loop_steps::add_candidate_term(TermSpec(drift), true, end.truth, &with_drift);
  const std::optional<std::pair<Model, std::string>> best = best_exact_norm_form(end, with_drift);
  ASSERT_TRUE(best.has_value());
  r.model = best->first;
  LoopRound lr = loop_steps::score(r.model, end.flights, end.truth, end.held, nullptr);
  lr.round = 1;
  lr.added = drift;
  r.rounds.push_back(lr);
  const DiagnoseOptions round_options = end.round_options();
  // The chance level of the model without the drift, at the drift's pace.
  Model without = loop_steps::without_term(r.model, TermSpec(drift));
  without.coefficients.resize(0);
  fit_model(without, end.flights);
  const double pace_s =
      loop_steps::term_correlation_time_s(TermSpec(drift), r.model, *end.flights[0]);
  const loop_steps::ChanceLevel chance =
      loop_steps::chance_level(without, end.flights, end.truth, round_options, pace_s);
  const LoopRound lw = loop_steps::score(without, end.flights, end.truth, end.held, nullptr);
  const double share =
      std::min(loop_steps::variance_share(lr.selection_std_nT, lw.selection_std_nT),
               loop_steps::variance_share(lr.confirmation_std_nT, lw.confirmation_std_nT));
  const double chance_left_nT = std::sqrt(1 - chance.share) * lw.heldout_std_nT;
  std::printf(
      "  run 137/1: held out %.4f nT with %s (%.2f%%), %.4f without; chance %.1f%% (%s) leaves "
      "%.4f nT\n",
      lr.heldout_std_nT, drift.c_str(), 100 * share, lw.heldout_std_nT, 100 * chance.share,
      chance.term.c_str(), chance_left_nT);
  ASSERT_GT(chance.share, 0.9);
  // Two draws of chance would leave less than the resolution; the drift leaves no more.
  EXPECT_FALSE(loop_steps::beyond_chance(share, chance));
  EXPECT_LT((1 - chance.share) * lw.heldout_std_nT, round_options.resolution_nT);
  EXPECT_LE(lr.heldout_std_nT, round_options.resolution_nT);
  EXPECT_GE(chance_left_nT, lr.heldout_std_nT + round_options.resolution_nT);
  EXPECT_TRUE(loop_steps::beyond_chance_to_the_resolution(lr.heldout_std_nT, lw.heldout_std_nT,
                                                          chance, round_options.resolution_nT));
  loop_steps::Round audit(end.context, 1, &r);
  std::set<std::string> audited;
  EXPECT_FALSE(audit.drop_chance_slow_term(round_options, &audited));
  EXPECT_EQ(audited.count(drift), 1u);
  const double next_nT = end.next_nT(r.model), tl_next_nT = end.next_nT(end.start);
  std::printf("  next flight: %.3f nT with the drift, %.3f nT without it, TL %.3f nT\n", next_nT,
              end.next_nT(without), tl_next_nT);
  EXPECT_LT(next_nT, 0.1 * tl_next_nT);
}

TEST(Discovery, AThermalIsComparedWithChanceAtItsOwnPace) {
  // Run 153, first aircraft, its states recorded: a product cur_flap*eng_rpm that the first
  // flight barely shows, and a 33.2 s thermal of cur_heat. The loop ends on current:cur_flap, TL
  // as the exact norm and the thermal's own term (correlation time 48 s). With the recorded
  // states read shifted in time, the search's best is a slower trend of fewer independent values
  // (here field:sw_pitot_heat|lp(64)|sat(0.698), 91.5 %; in the loop, whose model differs in its
  // digits, scalar:cur_ac_hi|lp(665), 77.3 %): against it the thermal (99.1 %; 94.8 % in the
  // loop) is not beyond chance, and taken out it leaves the next flight at 0.445 nT against
  // 0.089. Against the shifted terms as fast as it or faster (73.4 %), it is
  // (scripts/bench_discovery 1 153 half-several states draws=1).
  std::vector<sim::HiddenEffect> effects;
  const sim::Scenario a = test::discovery_scenario(153, 2, base_with_states(), 0, &effects);
  ASSERT_EQ(effects.size(), 2u);
  RoundAtTheEnd end(a, base_lambda(), {});
  const std::string thermal = "field:cur_heat|pow(2)|lp(33.1)|sat(14.5)";
  LoopResult& r = end.r;
  add_slow_round(end, end.exact_norm_with({"current:cur_flap", "bias", "norm"}), thermal, 1, &r);
  const Model with_thermal = r.model;
  const DiagnoseOptions round_options = end.round_options();
  // Its pace: the correlation time of its signal.
  const double pace_s =
      loop_steps::term_correlation_time_s(TermSpec(thermal), with_thermal, *end.flights[0]);
  Model without = loop_steps::without_term(with_thermal, TermSpec(thermal));
  without.coefficients.resize(0);
  fit_model(without, end.flights);
  const loop_steps::ChanceLevel any_pace =
      loop_steps::chance_level(without, end.flights, end.truth, round_options);
  const loop_steps::ChanceLevel own_pace =
      loop_steps::chance_level(without, end.flights, end.truth, round_options, pace_s);
  std::printf(
      "  run 153/0: %s, correlation time %.1f s; chance at any pace %.1f%% (%s), at its pace or "
      "faster %.1f%% (%s, %.1f s)\n",
      thermal.c_str(), pace_s, 100 * any_pace.share, any_pace.term.c_str(), 100 * own_pace.share,
      own_pace.term.c_str(), own_pace.correlation_s);
  EXPECT_GT(pace_s, 20.0);
  EXPECT_LT(pace_s, 100.0);
  ASSERT_FALSE(any_pace.term.empty());
  const double slowest_s =
      loop_steps::term_correlation_time_s(TermSpec(any_pace.term), without, *end.flights[0]);
  EXPECT_GT(slowest_s, 2 * pace_s) << any_pace.term;
  EXPECT_LE(own_pace.correlation_s, pace_s);
  EXPECT_LT(own_pace.share, any_pace.share - 0.1);
  EXPECT_EQ(own_pace.slower_term.empty(), false);
  // The audit keeps it, and with it the next flight is a third of what it is without.
  loop_steps::Round audit(end.context, 1, &r);
  std::set<std::string> audited;
  EXPECT_FALSE(audit.drop_chance_slow_term(round_options, &audited));
  EXPECT_EQ(audited.count(thermal), 1u);
  EXPECT_TRUE(std::find(r.model.terms.begin(), r.model.terms.end(), TermSpec(thermal)) !=
              r.model.terms.end());
  const double next_with_nT = end.next_nT(with_thermal), next_without_nT = end.next_nT(without);
  std::printf("  next flight: %.3f nT with it, %.3f nT without, TL %.3f nT\n", next_with_nT,
              next_without_nT, end.next_nT(end.start));
  EXPECT_LT(next_with_nT, 0.5 * next_without_nT);
}

TEST(Discovery, ATermThatStandsInForTwoEffectsGivesWayLookingOneRoundAhead) {
  // Run 227, first aircraft, its states recorded: a hysteresis of cur_srvo_m, a
  // 0.488 s lag of the scalar sensor and an inductive pick-up of cur_flap. Round 1 ranks
  // field:B|decay(0.269) first (held out 18.996 -> 2.465 nT): a decay of the body field is, to
  // first order, a lag and the pick-up's rate together. The lag, at 0.443 s while the other
  // effects pull it, leaves 3.541 nT. One round ahead, the decay and the term that follows it
  // leave 2.240 nT, the lag and its follower 1.587 nT: the lag is kept. Greedy, the loop ends
  // on the decay at 2.0 nT on the next flight (oracle 0.061); from the lag, on the true terms
  // at 0.043 nT (scripts/bench_discovery 1 227 half-several states draws=1).
  std::vector<sim::HiddenEffect> effects;
  const sim::Scenario a = test::discovery_scenario(227, 3, base_with_states(), 0, &effects);
  ASSERT_EQ(effects.size(), 3u);
  RoundAtTheEnd end(a, base_lambda(), {});
  LoopResult& r = end.r;
  const DiagnoseOptions round_options = end.round_options();
  const std::vector<loop_steps::Eligible> eligible = end.round_candidates();
  ASSERT_GE(eligible.size(), 2u);
  EXPECT_EQ(eligible.front().term.text().rfind("field:B|decay(", 0), 0u)
      << eligible.front().term.text();
  loop_steps::Round round(end.context, 1, &r);
  const std::vector<loop_steps::Eligible> ahead = round.looking_ahead(eligible, round_options);
  ASSERT_FALSE(ahead.empty());
  EXPECT_EQ(ahead.front().term.text().rfind("lag:", 0), 0u) << ahead.front().term.text();
  EXPECT_EQ(ahead.size(), eligible.size() - 1);  // the decay left out
  ASSERT_EQ(round.rejected().size(), 1u);
  std::printf("  %s: %s\n", round.rejected()[0].first.c_str(), round.rejected()[0].second.c_str());
  EXPECT_EQ(round.rejected()[0].first, eligible.front().term.text());
  EXPECT_NE(round.rejected()[0].second.find("one round ahead"), std::string::npos);
  ASSERT_TRUE(round.first_single(ahead));
  const LoopRound& kept = r.rounds.back();
  EXPECT_EQ(kept.added.rfind("lag:", 0), 0u) << kept.added;
  // The lag alone leaves more than the decay alone; its lag lies within 0.06 s of the truth.
  const double lag_s = std::stod(kept.added.substr(4));
  EXPECT_NEAR(lag_s, 0.488, 0.06);
  EXPECT_GT(kept.heldout_std_nT, 2.5);
  EXPECT_LT(kept.heldout_std_nT, 1.5 * 2.465);
  // The looking ahead off, the order is the diagnosis's.
  DiagnoseOptions greedy = end.options;
  greedy.look_ahead = false;
  const loop_steps::LoopContext greedy_context{end.start, end.flights, end.truth, end.held,
                                               nullptr,   greedy,      0.05};
  LoopResult r2 = end.r;
  loop_steps::Round as_ranked(greedy_context, 1, &r2);
  EXPECT_EQ(as_ranked.looking_ahead(eligible, round_options).front().term, eligible.front().term);
}

TEST(DiscoveryLong, LookingAheadAPathsNextTermReadsOtherChannels) {
  // Run 143, second aircraft, its states recorded: a drift of cur_bat_2, the product
  // cur_ac_hi*sw_pitot_heat and a ripple of cur_outpwr. Round 1 ranks the true product first
  // (0.888 -> 0.777 nT held out); the runner-up cur_ac_hi*cur_bat_1 leaves 0.781 nT. Followed by
  // scalar:cur_bat_1|lp(2.88), a second term of its own channel, the runner-up left 0.711 nT
  // and took the round: the next flight went from 0.676 to 0.874 nT (TL 1.063). A term of the
  // path's own channel writes that channel's shape, not another effect: the look-ahead does not
  // count it, and the true product stays (scripts/bench_discovery 1 143 half-several states
  // draws=2).
  std::vector<sim::HiddenEffect> effects;
  const sim::Scenario a = test::discovery_scenario(143, 3, base_with_states(), 1, &effects);
  ASSERT_EQ(effects.size(), 3u);
  RoundAtTheEnd end(a, base_lambda(), {});
  LoopResult& r = end.r;
  const DiagnoseOptions round_options = end.round_options();
  const std::vector<loop_steps::Eligible> eligible = end.round_candidates();
  ASSERT_GE(eligible.size(), 2u);
  EXPECT_EQ(eligible.front().term.text().rfind("field:cur_ac_hi*sw_pitot_heat", 0), 0u)
      << eligible.front().term.text();
  loop_steps::Round round(end.context, 1, &r);
  const std::vector<loop_steps::Eligible> ahead = round.looking_ahead(eligible, round_options);
  ASSERT_EQ(ahead.size(), eligible.size());
  EXPECT_EQ(ahead.front().term, eligible.front().term);
  for (const auto& [term, why] : round.rejected()) ADD_FAILURE() << term << ": " << why;
  ASSERT_TRUE(round.first_single(ahead));
  EXPECT_EQ(r.rounds.back().added.rfind("field:cur_ac_hi*sw_pitot_heat", 0), 0u)
      << r.rounds.back().added;
  EXPECT_NEAR(r.rounds.back().heldout_std_nT, 0.777, 0.01);
}

TEST(Discovery, AProductsFactorThatEarnsNoPlaceIsDropped) {
  // Run 128, third aircraft: the wire of cur_com_1. The first round takes its field times
  // cur_outpwr, low-passed, which ranks first; no term passes after it and the loop ended there,
  // naming cur_outpwr, 0.631 nT on the next flight against the oracle's 0.498
  // (scripts/bench_discovery 1 128 half-several states draws=3 keep-factors). Without the
  // factor the term does better on the held-out lines: it takes the product's place.
  const sim::Scenario base = base_with_states();
  std::vector<sim::HiddenEffect> effects;
  {
    const sim::Scenario a = test::discovery_scenario(128, 1, base, 2, &effects);
    ASSERT_EQ(effects.size(), 1u);
    ASSERT_EQ(effects[0].channel, "cur_com_1");
    RoundAtTheEnd end(a, base_lambda(), {"field:cur_com_1*cur_outpwr|lp(0.2)"});
    loop_steps::Round round(end.context, 2, &end.r);
    ASSERT_TRUE(round.drop_idle_factors());
    const LoopRound& lr = end.r.rounds.back();
    ASSERT_EQ(lr.replaced.size(), 1u);
    EXPECT_EQ(lr.replaced[0].first, "field:cur_com_1*cur_outpwr|lp(0.2)");
    EXPECT_EQ(lr.added, "field:cur_com_1|lp(0.2)");
    const double before_nT = end.r.rounds[0].heldout_std_nT, after_nT = lr.heldout_std_nT;
    const double next_before_nT = evaluate_model(end.model, end.fb.flight, "mag_1_c", false).std_nT;
    const double next_after_nT =
        evaluate_model(end.r.model, end.fb.flight, "mag_1_c", false).std_nT;
    std::printf("  %s -> %s: held out %.4f -> %.4f nT, next flight %.3f -> %.3f nT (%s)\n",
                lr.replaced[0].first.c_str(), lr.added.c_str(), before_nT, after_nT, next_before_nT,
                next_after_nT, lr.replaced[0].second.c_str());
    // Not beaten by the product: within the accepted share or the resolution of it.
    const DiagnoseOptions o;
    EXPECT_TRUE(after_nT < before_nT + o.resolution_nT ||
                after_nT * after_nT * (1 - o.accept_fraction) < before_nT * before_nT);
    EXPECT_LT(next_after_nT, next_before_nT);
    EXPECT_NEAR(lr.explained, loop_steps::variance_share(after_nT, before_nT), 1e-12);
    EXPECT_GT(lr.explained, 0);  // here the term without the factor does better
    loop_steps::Round again(end.context, 3, &end.r);
    EXPECT_FALSE(again.drop_idle_factors());  // no product left
  }
  {
    // Run 103, second aircraft: a current times the flap angle that moves it (with a relay of
    // the same current and a drift), found exactly. Each factor earns its place.
    const sim::Scenario a = test::discovery_scenario(103, 3, base, 1, &effects);
    RoundAtTheEnd end(
        a, base_lambda(),
        {"field:cur_flap*flap_deg", "scalar:cur_srvo_m|lp(240)", "field:cur_flap|step(0.0101)"});
    loop_steps::Round round(end.context, 4, &end.r);
    EXPECT_FALSE(round.drop_idle_factors()) << end.r.rounds.back().added;
  }
}

TEST(Discovery, ASteadyFactorThatExplainsWhatRemainsJoinsItsTerm) {
  // Run 141, first aircraft, its states recorded: the field of cur_strb times the engine speed
  // (within about 5 % of its mean) and of cur_com_1 times the flap angle. The loop ends with
  // field:cur_com_1*flap_deg, the exact norm and current:cur_strb, "below the resolution", and
  // lists eng_rpm among the channels the wire may scale with unseen; 0.033 nT on the next flight
  // (scripts/bench_discovery 1 141 half-several states draws=3 no-steady-factors). Once every
  // other effect is written, the engine speed's modulation is most of what remains, on both
  // halves, though it gains less than a new term must: the product takes the wire's place.
  const sim::Scenario base = base_with_states();
  std::vector<sim::HiddenEffect> effects;
  const sim::Scenario a = test::discovery_scenario(141, 2, base, 0, &effects);
  const sim::HiddenEffect* product = drawn(effects, "product", "cur_strb");
  ASSERT_TRUE(product) << "run 141 draws no product of cur_strb";
  ASSERT_EQ(product->channel2, "eng_rpm");
  RoundAtTheEnd end(a, 1e-4, {});
  const Model m =
      end.exact_norm_with({"field:cur_com_1*flap_deg", "bias", "norm", "current:cur_strb"});
  LoopResult& r = end.r;
  r.model = m;
  LoopRound kept = loop_steps::score(m, end.flights, end.truth, end.held, nullptr);
  const DiagnoseOptions o;
  // What the round that kept the wire lists beside it (a term of about half a nanotesla).
  kept.added = "current:cur_strb";
  kept.steady_factors =
      loop_steps::steady_factors(end.flights, {"cur_strb"}, end.truth, 0.5, o.resolution_nT);
  ASSERT_TRUE(std::any_of(kept.steady_factors.begin(), kept.steady_factors.end(),
                          [](const auto& f) { return f.first == "eng_rpm"; }));
  r.rounds.push_back(kept);
  const Model model_before = r.model;
  loop_steps::Round round(end.context, 4, &r);
  ASSERT_TRUE(round.steady_factor_in_place());
  const LoopRound& now = r.rounds.back();
  ASSERT_EQ(now.replaced.size(), 1u);
  EXPECT_EQ(now.replaced[0].first, "current:cur_strb");
  EXPECT_EQ(now.added, "field:cur_strb*eng_rpm");
  const double next_before_nT = end.next_nT(model_before), next_now_nT = end.next_nT(r.model);
  std::printf(
      "  %s -> %s: held out %.4f -> %.4f nT (halves %.4f -> %.4f, %.4f -> %.4f); next "
      "flight %.3f -> %.3f nT\n",
      now.replaced[0].first.c_str(), now.added.c_str(), kept.heldout_std_nT, now.heldout_std_nT,
      kept.selection_std_nT, now.selection_std_nT, kept.confirmation_std_nT,
      now.confirmation_std_nT, next_before_nT, next_now_nT);
  // Below the resolution, by most of the variance, and on each half by half of it here.
  EXPECT_LT(kept.heldout_std_nT - now.heldout_std_nT, o.resolution_nT);
  EXPECT_GE(loop_steps::variance_share(now.heldout_std_nT, kept.heldout_std_nT),
            loop_steps::kFactorShare);
  EXPECT_GE(loop_steps::variance_share(now.selection_std_nT, kept.selection_std_nT), 0.5);
  EXPECT_GE(loop_steps::variance_share(now.confirmation_std_nT, kept.confirmation_std_nT), 0.5);
  EXPECT_LT(next_now_nT, 0.5 * next_before_nT);
  // The factor keeps its place by the same test: no step takes it out again.
  loop_steps::Round simplify(end.context, 5, &r);
  EXPECT_FALSE(simplify.drop_idle_factors()) << r.rounds.back().added;
  loop_steps::Round again(end.context, 5, &r);
  EXPECT_FALSE(again.steady_factor_in_place()) << r.rounds.back().added;
}

TEST(Discovery, AFactorTheSearchPairedWithAKeptTermJoinsIt) {
  // Run 196, third aircraft, its states recorded: the field of cur_flap times the flap angle,
  // which the first flight holds near 10 degrees but for a few deployments to 20 (scripts/
  // bench_discovery 1 196 half-several states draws=3). With TL as the exact norm, the round
  // ranks current:cur_flap and field:cur_flap*flap_deg within a point of each other on the
  // selection lines and keeps the simpler; on the confirmation lines the product explains
  // more, and what it leaves is a third of the wire's, but the difference is below the
  // resolution a new term must gain. flap_deg varies too much to be listed as steady: only the
  // pairing of the round's search names it.
  const sim::Scenario base = base_with_states();
  std::vector<sim::HiddenEffect> effects;
  const sim::Scenario a = test::discovery_scenario(196, 1, base, 2, &effects);
  const sim::HiddenEffect* product = drawn(effects, "product", "cur_flap");
  ASSERT_TRUE(product) << "run 196 draws no product of cur_flap";
  ASSERT_EQ(product->channel2, "flap_deg");
  RoundAtTheEnd end(a, 1e-6, {});
  LoopResult& r = end.r;
  r.model = end.exact_norm_with({"bias", "norm"});
  r.rounds.push_back(loop_steps::score(r.model, end.flights, end.truth, end.held, nullptr));
  // The round: its eligible candidates, and the single term it keeps.
  const Diagnosis dx = diagnose(r.model, end.fa.flight, end.truth);
  const std::vector<loop_steps::Eligible> eligible =
      loop_steps::eligible_candidates({dx}, 0.05, false);
  size_t kept = eligible.size();
  for (size_t k = 0; k < eligible.size(); ++k)
    if (eligible[k].term.text() == "current:cur_flap") kept = k;
  ASSERT_LT(kept, eligible.size()) << "current:cur_flap is not eligible";
  const std::vector<std::string> paired = loop_steps::paired_factors(eligible, kept);
  EXPECT_NE(std::find(paired.begin(), paired.end(), "flap_deg"), paired.end());
  loop_steps::Round keep(end.context, 2, &r);
  ASSERT_TRUE(keep.first_single(eligible));
  ASSERT_EQ(r.rounds.back().added, "current:cur_flap");
  const LoopRound wire = r.rounds.back();
  EXPECT_EQ(wire.paired_factors, paired);
  const Model with_wire = r.model;
  // Not a steady factor: without the pairing no product takes the wire's place.
  {
    LoopResult unpaired = r;
    unpaired.rounds.back().paired_factors.clear();
    loop_steps::Round round(end.context, 3, &unpaired);
    const bool changed = round.steady_factor_in_place();
    EXPECT_TRUE(!changed || unpaired.rounds.back().added.find("flap_deg") == std::string::npos)
        << unpaired.rounds.back().added;
  }
  loop_steps::Round round(end.context, 3, &r);
  ASSERT_TRUE(round.steady_factor_in_place());
  const LoopRound& now = r.rounds.back();
  ASSERT_EQ(now.replaced.size(), 1u);
  EXPECT_EQ(now.replaced[0].first, "current:cur_flap");
  EXPECT_EQ(now.added, "field:cur_flap*flap_deg");
  EXPECT_NE(now.replaced[0].second.find("paired"), std::string::npos) << now.replaced[0].second;
  const double next_before_nT = end.next_nT(with_wire), next_now_nT = end.next_nT(r.model);
  std::printf("  %s -> %s: held out %.4f -> %.4f nT; next flight %.3f -> %.3f nT\n",
              now.replaced[0].first.c_str(), now.added.c_str(), wire.heldout_std_nT,
              now.heldout_std_nT, next_before_nT, next_now_nT);
  EXPECT_LT(wire.heldout_std_nT - now.heldout_std_nT, DiagnoseOptions().resolution_nT);
  EXPECT_GE(loop_steps::variance_share(now.heldout_std_nT, wire.heldout_std_nT), 0.5);
  EXPECT_LT(next_now_nT, 0.25 * next_before_nT);
}

TEST(Discovery, AWireOfAnIdleFactorKeepsItsName) {
  // Run 146, first aircraft, its states recorded: the wire of cur_heat alone. Every channel the
  // wire may scale with unseen is tried in its place and none explains what remains.
  const sim::Scenario base = base_with_states();
  std::vector<sim::HiddenEffect> effects;
  const sim::Scenario a = test::discovery_scenario(146, 1, base, 0, &effects);
  ASSERT_EQ(effects.size(), 1u);
  ASSERT_EQ(effects[0].type, "wire");
  ASSERT_EQ(effects[0].channel, "cur_heat");
  RoundAtTheEnd end(a, base_lambda(), {"current:cur_heat"});
  LoopRound& kept = end.r.rounds.back();
  kept.added = "current:cur_heat";
  // Every recorded state that varies by less than a fifth of its mean.
  kept.steady_factors = loop_steps::steady_factors(end.flights, {"cur_heat"}, end.truth, 1.0, 0.2);
  ASSERT_GE(kept.steady_factors.size(), 3u);
  loop_steps::Round round(end.context, 2, &end.r);
  EXPECT_FALSE(round.steady_factor_in_place()) << end.r.rounds.back().added;
  EXPECT_EQ(end.r.rounds.size(), 1u);
}

TEST(Discovery, WithTheLineJackknifeATermMustGainBeyondItsBestLine) {
  // Four held-out lines of 10 nT² each. A new channel term that takes 8 nT² from one line only
  // (a clock's step, a state that fits one line's wander) lowers the pooled error by 20 %, and
  // the other lines' by nothing: refused with the jackknife, kept without it. One that takes
  // 2 nT² from every line keeps 20 % on the other three and passes either way.
  const auto round = [](std::vector<double> line_ss, bool with_term) {
    LoopRound r;
    r.line_ss_nT2 = line_ss;
    double ss = 0;
    for (double v : line_ss) ss += v;
    r.heldout_std_nT = std::sqrt(ss / 400.0);
    if (with_term) r.channel_terms = {"current:cur_bat_2"};
    return r;
  };
  const LoopRound now = round({10, 10, 10, 10}, false);
  const LoopRound one_line = round({2, 10, 10, 10}, true);
  const LoopRound every_line = round({8, 8, 8, 8}, true);
  DiagnoseOptions pooled;
  DiagnoseOptions jackknife;
  jackknife.line_jackknife = true;
  EXPECT_EQ(loop_steps::refusal(one_line, now, pooled), "");
  const std::string why = loop_steps::refusal(one_line, now, jackknife);
  EXPECT_NE(why.find("without the held-out line where it gains most (100.0% of its gain)"),
            std::string::npos)
      << why;
  EXPECT_EQ(loop_steps::refusal(every_line, now, jackknife), "");
  // A change that adds no channel term (a ridge strength) is judged pooled.
  LoopRound ridge = one_line;
  ridge.channel_terms.clear();
  EXPECT_EQ(loop_steps::refusal(ridge, now, jackknife), "");
}

TEST(Discovery, ABusTheFlightHoldsSteadyIsListedAsAFactorOfTheWire) {
  // Run 130, first aircraft, its states recorded: the field of cur_heat times vol_outpwr, a bus
  // held at 27.8 V within a few tenths of a volt, which no flight tells apart from the heater
  // current's own wire. The channels a kept term of cur_heat may scale with unseen
  // (loop_steps::steady_factors, what the loop lists beside the term it keeps;
  // DiscoveryLong.AProductWithABusVoltageHeldSteady... runs the loop): the bus among them, each
  // so steady that the product differs from the term by less than the resolution, and no channel
  // that moves.
  const sim::Scenario base = base_with_states();
  std::vector<sim::HiddenEffect> effects;
  const sim::Scenario a = test::discovery_scenario(130, 1, base, 0, &effects);
  ASSERT_EQ(effects.size(), 1u);
  ASSERT_EQ(effects[0].channel, "cur_heat");
  const sim::Simulation fa = sim::simulate(a, Igrf::installed());
  Model tl = load_model_yaml(test::source_dir() + "/config/models/tl_sim.yaml");
  tl.fit.lambda = base_lambda();
  fit_model(tl, {&fa.flight});
  Model wire = tl;
  wire.add_term(TermSpec("current:cur_heat"));
  fit_model(wire, {&fa.flight});
  const auto held = held_out_as_diagnose_splits(fa.flight, tl);
  const double without_nT =
      loop_steps::score(tl, {&fa.flight}, "mag_1_c", held, nullptr).heldout_std_nT;
  const double with_nT =
      loop_steps::score(wire, {&fa.flight}, "mag_1_c", held, nullptr).heldout_std_nT;
  const double term_nT = std::sqrt(without_nT * without_nT - with_nT * with_nT);
  const double resolution_nT = DiagnoseOptions{}.resolution_nT;
  const auto steady =
      loop_steps::steady_factors({&fa.flight}, {"cur_heat"}, "mag_1_c", term_nT, resolution_nT);
  std::printf("  held out %.4f -> %.4f nT with the wire (explains %.3f nT); steady:", without_nT,
              with_nT, term_nT);
  std::set<std::string> names;
  for (const auto& [factor, relative] : steady) {
    std::printf(" %s %.3f %%", factor.c_str(), 100 * relative);
    names.insert(factor);
    EXPECT_LT(relative * term_nT, resolution_nT) << factor;
    // The relative std, from the flight's own samples.
    const Eigen::VectorXd x = fa.flight.column(factor);
    const double mean = x.mean();
    const double sd = std::sqrt((x.array() - mean).square().mean());
    EXPECT_NEAR(relative, sd / std::abs(mean), 1e-3 * relative + 1e-12) << factor;
  }
  std::printf("\n");
  EXPECT_GT(term_nT, 10 * resolution_nT);  // the wire explains far more than the resolution
  EXPECT_TRUE(names.count("vol_outpwr")) << "the bus is not among the steady channels";
  EXPECT_FALSE(names.count("cur_heat"));
  // A switched current, an engine speed that changes with the flight's phases, a rate: never.
  for (const char* moving : {"cur_strb", "cur_tank", "roll_rate", "flap_deg", "eng_rpm"})
    EXPECT_FALSE(names.count(moving)) << moving;
  // Steadiest first.
  for (size_t k = 1; k < steady.size(); ++k) EXPECT_LE(steady[k - 1].second, steady[k].second);
}

TEST(Discovery, WhatTellsTwoLookAlikesApartIsTheChannelTheirRatioFollows) {
  // A coordinated turn's lateral acceleration is the yaw rate times the airspeed: on a flight
  // held near one speed the two are look-alikes, and the airspeed is what tells them apart
  // (loop_steps::look_alike_ratio). Closed form: 10 min at 10 Hz, turns every minute, the
  // airspeed 100 +- 10 m/s over a slow cycle; a battery voltage exactly twice another (their
  // ratio follows nothing); a current that switches at random.
  const Eigen::Index n = 6000;
  const double dt = 0.1, pi = 3.14159265358979323846;
  FlightData f;
  Eigen::VectorXd tt(n), yaw(n), tas(n), acc(n), vol_a(n), vol_b(n), cur(n);
  std::srand(7);
  for (Eigen::Index i = 0; i < n; ++i) {
    const double t = dt * static_cast<double>(i);
    tt[i] = t;
    yaw[i] = 3.0 * std::sin(2 * pi * t / 60.0);            // deg/s
    tas[i] = 100.0 + 10.0 * std::sin(2 * pi * t / 700.0);  // m/s
    acc[i] = yaw[i] * pi / 180.0 * tas[i];                 // m/s^2
    vol_a[i] = 28.0 + 0.1 * std::cos(2 * pi * t / 37.0);
    vol_b[i] = 2.0 * vol_a[i];
    cur[i] = (std::rand() % 2) ? 3.0 : 0.5;
  }
  f.set("tt", tt);
  for (const auto& [name, x] :
       std::vector<std::pair<const char*, Eigen::VectorXd>>{{"yaw_rate", yaw},
                                                            {"tas", tas},
                                                            {"ins_acc_y", acc},
                                                            {"vol_bat_1", vol_a},
                                                            {"vol_bat_2", vol_b},
                                                            {"cur_strb", cur},
                                                            {"mag_1_c", Eigen::VectorXd::Zero(n)}})
    f.set(name, x);
  const auto ratio = loop_steps::look_alike_ratio({&f}, {"ins_acc_y"}, {"yaw_rate"}, "mag_1_c");
  ASSERT_TRUE(ratio.has_value());
  EXPECT_EQ(ratio->channel, "tas");
  EXPECT_EQ(ratio->kept_channel, "ins_acc_y");
  EXPECT_EQ(ratio->alike_channel, "yaw_rate");
  EXPECT_GT(ratio->correlation, 0.999999);  // the ratio is pi/180 times the airspeed
  const double sd = std::sqrt((tas.array() - tas.mean()).square().mean());
  EXPECT_NEAR(ratio->relative_std, sd / tas.mean(), 1e-9);
  // Each way round: yaw rate / acceleration is 180/pi over the airspeed, which falls as it rises.
  const auto inverse = loop_steps::look_alike_ratio({&f}, {"yaw_rate"}, {"ins_acc_y"}, "mag_1_c");
  ASSERT_TRUE(inverse.has_value());
  EXPECT_EQ(inverse->channel, "tas");
  EXPECT_LT(inverse->correlation, -0.99);
  // Two channels in a constant ratio: no channel tells them apart.
  EXPECT_FALSE(loop_steps::look_alike_ratio({&f}, {"vol_bat_2"}, {"vol_bat_1"}, "mag_1_c"));
  // The airspeed as the reference: no other channel follows the ratio.
  EXPECT_FALSE(loop_steps::look_alike_ratio({&f}, {"ins_acc_y"}, {"yaw_rate"}, "tas"));
  // A look-alike of two channels, the lateral acceleration times a bus held at 28 +- 0.1 V: read
  // through the acceleration alone, the ratio follows the airspeed exactly.
  const auto product =
      loop_steps::look_alike_ratio({&f}, {"yaw_rate"}, {"ins_acc_y", "vol_bat_1"}, "mag_1_c");
  ASSERT_TRUE(product.has_value());
  EXPECT_EQ(product->channel, "tas");
  EXPECT_EQ(product->kept_channel, "yaw_rate");
  EXPECT_EQ(product->alike_channel, "ins_acc_y");
  EXPECT_LT(product->correlation, -0.99);
  // The bus's own ratio to the product: it follows the airspeed (1 / tas) only through the
  // acceleration, and the bus is never the channel named.
  EXPECT_NE(product->channel, "vol_bat_1");
  // Sets that share a channel are no pair of look-alikes.
  EXPECT_FALSE(
      loop_steps::look_alike_ratio({&f}, {"yaw_rate"}, {"yaw_rate", "vol_bat_1"}, "mag_1_c"));
  // A channel the flights do not record.
  EXPECT_FALSE(loop_steps::look_alike_ratio({&f}, {"ins_acc_y"}, {"cur_heat"}, "mag_1_c"));
}

TEST(DiscoveryLong, AProductWithABusVoltageHeldSteadyIsReportedBesideTheWire) {
  // Run 130, first aircraft, its states recorded: the field of cur_heat times vol_outpwr, a bus
  // held at 27.8 V within a few tenths of a volt. The product's columns differ from the heater
  // current's own by that voltage's few tenths of a percent: no flight tells them apart, and the
  // loop keeps the current's wire (0.085 nT on the next flight, oracle 0.090;
  // scripts/bench_discovery 1 130 half-several states verbose). What it must say is that the
  // current's field may scale with a channel the flight holds steady, the bus among them.
  const sim::Scenario base = base_with_states();
  const Model tl = load_model_yaml(test::source_dir() + "/config/models/tl_sim.yaml");
  const test::DiscoveryRun d = test::discovery_run(130, 1, base, tl, {}, 0);
  ASSERT_EQ(d.true_channels, (std::set<std::string>{"cur_heat", "vol_outpwr"})) << d.effects;
  const double resolution_nT = DiagnoseOptions{}.resolution_nT;
  std::set<std::string> steady;  // the steady factors of the round keeping a term of cur_heat
  for (size_t i = 1; i < d.rounds.size(); ++i) {
    const LoopRound& lr = d.rounds[i];
    if (lr.added.find("cur_heat") == std::string::npos) continue;
    const double term_nT =
        std::sqrt(std::pow(d.rounds[i - 1].heldout_std_nT, 2) - std::pow(lr.heldout_std_nT, 2));
    std::printf("  round %d: %s, held out %.4f nT (explains %.3f nT); steady:", lr.round,
                lr.added.c_str(), lr.heldout_std_nT, term_nT);
    for (const auto& [factor, relative] : lr.steady_factors) {
      std::printf(" %s %.3f %%", factor.c_str(), 100 * relative);
      steady.insert(factor);
      // Steady enough that the product's difference from the term is below the resolution.
      EXPECT_LT(relative * term_nT, resolution_nT) << factor;
      EXPECT_NE(factor, "cur_heat");
    }
    std::printf("\n");
  }
  std::printf("  next flight: TL %.3f, loop %.3f, oracle %.3f nT\n", d.tl_next_nT, d.loop_next_nT,
              d.oracle_next_nT);
  EXPECT_TRUE(d.near_oracle());
  EXPECT_TRUE(steady.count("vol_outpwr")) << "the bus is not among the steady channels";
  // A switched current, an engine speed that changes with the flight's phases, a rate: never.
  for (const char* moving : {"cur_strb", "cur_tank", "roll_rate", "flap_deg"})
    EXPECT_FALSE(steady.count(moving)) << moving;
  EXPECT_TRUE(d.names_truth_among_look_alikes());
  EXPECT_FALSE(d.names_truth());
  // The product's term does no better on the flight than the heater current's own in its place:
  // the flight does not show the bus, and the benchmark says so.
  EXPECT_FALSE(d.shows_every_effect);
  EXPECT_EQ(d.unshown_effects.size(), 1u);
}

TEST(Discovery, ALookAlikeThatDoesBetterTakesTheKeptTermsPlace) {
  // Run 119, first aircraft, its states recorded: a relay of cur_srvo_i, a product
  // cur_com_1*vol_fan and a flex of the yaw rate. With the relay and the product written, the
  // screen ranks a term of the true airspeed first on the selection lines; it passes alone, but
  // the yaw rate's term and the lateral acceleration's (the yaw rate times the speed, which no
  // flight of the simulator tells from it) leave less on the held-out lines
  // (scripts/bench_discovery 1 119 half-several states draws=3 why first-kept). The round tries
  // the eligible terms in rank order: the first kept gives way to the look-alike that beats it by
  // what a term must gain, and the other of the two is named beside it.
  const sim::Scenario base = base_with_states();
  std::vector<sim::HiddenEffect> effects;
  const sim::Scenario a = test::discovery_scenario(119, 3, base, 0, &effects);
  ASSERT_TRUE(drawn(effects, "flex", "yaw_rate")) << "run 119 draws no flex of the yaw rate";
  RoundAtTheEnd end(a, base_lambda(), {"field:cur_srvo_i|step(0.307)", "field:cur_com_1*vol_fan"});
  const auto e = [](const char* t) { return loop_steps::Eligible{TermSpec(t), false, 0.1, NAN}; };
  const std::vector<loop_steps::Eligible> eligible = {
      e("field:tas|lp(0.894)"), e("field:yaw_rate|lp(0.2)"), e("field:ins_acc_y|lp(0.2)"),
      e("field:pitot_p|delay(0.236)")};
  const auto run_round = [&](const DiagnoseOptions& options, LoopResult* r) {
    *r = end.r;
    const loop_steps::LoopContext context{end.start, end.flights, end.truth, end.held,
                                          nullptr,   options,     0.05};
    loop_steps::Round round(context, 3, r);
    return round.first_single(eligible);
  };
  DiagnoseOptions first_kept;
  first_kept.better_look_alike = false;
  LoopResult with_first, with_better;
  ASSERT_TRUE(run_round(first_kept, &with_first));
  ASSERT_TRUE(run_round(DiagnoseOptions{}, &with_better));
  const LoopRound& first = with_first.rounds.back();
  const LoopRound& better = with_better.rounds.back();
  EXPECT_EQ(first.added, "field:tas|lp(0.894)");
  const std::set<std::string> yaw = {"field:yaw_rate|lp(0.2)", "field:ins_acc_y|lp(0.2)"};
  EXPECT_TRUE(yaw.count(better.added)) << better.added;
  // The other of the two is named beside it; the airspeed's term, beaten, is not.
  std::set<std::string> alikes;
  for (const auto& [term, nT] : better.look_alikes) alikes.insert(term);
  for (const std::string& t : yaw) {
    if (t != better.added) {
      EXPECT_TRUE(alikes.count(t)) << t;
    }
  }
  EXPECT_FALSE(alikes.count("field:tas|lp(0.894)"));
  // What would tell the two apart: their channels' ratio follows the airspeed, which the flight
  // holds within about one percent.
  const auto yaw_alike = std::find_if(
      better.look_alike_ratios.begin(), better.look_alike_ratios.end(),
      [&](const LookAlikeRatio& x) { return yaw.count(x.term) && x.term != better.added; });
  ASSERT_NE(yaw_alike, better.look_alike_ratios.end()) << "no ratio for the other yaw term";
  const LookAlikeRatio& q = *yaw_alike;
  EXPECT_EQ(q.channel, "tas");
  EXPECT_GT(std::abs(q.correlation), 0.99);
  const Eigen::VectorXd tas = end.fa.flight.column("tas");
  const double tas_sd = std::sqrt((tas.array() - tas.mean()).square().mean());
  EXPECT_NEAR(q.relative_std, tas_sd / tas.mean(), 1e-6);
  EXPECT_LT(q.relative_std, 0.05);
  std::printf("  %s / %s follows %s (r %.4f), relative std %.3f %%\n", q.kept_channel.c_str(),
              q.alike_channel.c_str(), q.channel.c_str(), q.correlation, 100 * q.relative_std);
  bool said = false;
  for (const auto& [what, why] : better.rejected)
    said = said || (what == "field:tas|lp(0.894)" &&
                    why.find("a look-alike of another channel does better") != std::string::npos);
  EXPECT_TRUE(said) << "the round does not say why the first term gave way";
  // Better by what a term must gain, on the held-out lines and on the aircraft's next flight.
  const double next_first_nT =
      evaluate_model(with_first.model, end.fb.flight, "mag_1_c", false).std_nT;
  const double next_better_nT =
      evaluate_model(with_better.model, end.fb.flight, "mag_1_c", false).std_nT;
  std::printf("  %s %.4f nT held out, %.3f nT next flight; %s %.4f nT, %.3f nT\n",
              first.added.c_str(), first.heldout_std_nT, next_first_nT, better.added.c_str(),
              better.heldout_std_nT, next_better_nT);
  EXPECT_LT(std::pow(better.heldout_std_nT / first.heldout_std_nT, 2), 0.98);
  EXPECT_LT(better.heldout_std_nT, first.heldout_std_nT - DiagnoseOptions{}.resolution_nT);
  EXPECT_LT(next_better_nT, next_first_nT);
}

TEST(Discovery, ALookAlikeThatFitsTheRowsItIsSizedOnWorseKeepsOutOfTheKeptTermsPlace) {
  // Run 1, first aircraft: a heater of cur_outpwr (50.7 s) and a 751 s drift of cur_srvo_m. The
  // screen ranks the bus current's term first; the output bus voltage sags under the same load
  // and wanders slowly besides (a random walk shared by the buses), and its term leaves less on
  // the held-out lines of this flight: the wander follows the drift there. Sized on the
  // calibration rows, it fits them worse than the current's term, and on the aircraft's next
  // flight it ends above TL (scripts/bench_discovery 1 1 half-several states draws=3 why).
  const sim::Scenario base = base_with_states();
  std::vector<sim::HiddenEffect> effects;
  const sim::Scenario a = test::discovery_scenario(1, 2, base, 0, &effects);
  ASSERT_TRUE(drawn(effects, "thermal", "cur_outpwr")) << "run 1 draws no heater of cur_outpwr";
  RoundAtTheEnd end(a, base_lambda(), {});
  const std::string current = "scalar:cur_acpwr|lp(49.2)|sat(7.03)";
  const std::string voltage = "field:vol_outpwr|lp(53.9)";
  const std::vector<loop_steps::Eligible> eligible = {{TermSpec(current), true, 0.3, NAN},
                                                      {TermSpec(voltage), true, 0.3, NAN}};
  LoopResult r = end.r;
  loop_steps::Round round(end.context, 1, &r);
  ASSERT_TRUE(round.first_single(eligible));
  const LoopRound& kept = r.rounds.back();
  EXPECT_EQ(kept.added, current);
  // The voltage is named beside it, with less left on the held-out lines: it did not take the
  // place because it fits the calibration rows worse.
  double voltage_nT = NAN;
  for (const auto& [term, nT] : kept.look_alikes)
    if (term == voltage) voltage_nT = nT;
  ASSERT_TRUE(std::isfinite(voltage_nT)) << "the bus voltage's term is not named beside it";
  Model with_voltage = end.model;
  loop_steps::add_candidate_term(TermSpec(voltage), true, end.truth, &with_voltage);
  fit_model(with_voltage, end.flights);
  const LoopRound v = loop_steps::score(with_voltage, end.flights, end.truth, end.held, nullptr);
  EXPECT_NEAR(v.heldout_std_nT, voltage_nT, 1e-9);
  std::printf("  %s: %.4f nT held out, %.4f nT on the calibration rows; %s: %.4f nT, %.4f nT\n",
              current.c_str(), kept.heldout_std_nT, kept.calibration_std_nT, voltage.c_str(),
              v.heldout_std_nT, v.calibration_std_nT);
  EXPECT_LT(std::pow(v.heldout_std_nT / kept.heldout_std_nT, 2), 0.98);
  EXPECT_GT(v.calibration_std_nT, 1.1 * kept.calibration_std_nT);
  // On the next flight the current's term stays below TL and the voltage's does not.
  const double tl_next_nT = evaluate_model(end.start, end.fb.flight, "mag_1_c", false).std_nT;
  const double kept_next_nT = evaluate_model(r.model, end.fb.flight, "mag_1_c", false).std_nT;
  const double voltage_next_nT =
      evaluate_model(with_voltage, end.fb.flight, "mag_1_c", false).std_nT;
  std::printf("  next flight: TL %.3f, %s %.3f, %s %.3f nT\n", tl_next_nT, current.c_str(),
              kept_next_nT, voltage.c_str(), voltage_next_nT);
  EXPECT_LT(kept_next_nT, tl_next_nT);
  EXPECT_GT(voltage_next_nT, kept_next_nT);
}

TEST(Discovery, AKeptSlowTermGivesWayToTheDriftsOwnChannel) {
  // Run 1, first aircraft: a heater of cur_outpwr (50.7 s) and a 751 s drift of cur_srvo_m. With
  // TL as given and the ridge chosen (fit.lambda 1e-5), the loop keeps the heater, then
  // scalar:vol_bat_1|lp(7.06), a battery voltage that charges over the flight and follows the
  // drift there, and names the drift's own scalar:cur_srvo_m|lp(665) among its look-alikes
  // (magcomp diagnose --apply --tl-as-given on the run's first flight). Both are slow terms, sized
  // by the slow stage. Once the rounds are spent, the drift's channel takes the voltage's place
  // with every other term in place, and carries to the next flight, where the voltage does not.
  const sim::Scenario base =
      sim::load_scenario(test::source_dir() + "/config/scenarios/random_base.yaml");
  std::vector<sim::HiddenEffect> effects;
  const sim::Scenario a = test::discovery_scenario(1, 2, base, 0, &effects);
  ASSERT_TRUE(drawn(effects, "drift", "cur_srvo_m")) << "run 1 draws no drift of cur_srvo_m";
  RoundAtTheEnd end(a, 1e-5, {});
  const std::string heater = "scalar:cur_outpwr|lp(53)";
  const std::string voltage = "scalar:vol_bat_1|lp(7.06)";
  const std::string drift = "scalar:cur_srvo_m|lp(665)";
  LoopResult r = end.with_slow_term(heater);
  loop_steps::add_candidate_term(TermSpec(voltage), true, end.truth, &r.model);
  fit_model(r.model, end.flights);
  LoopRound kept = loop_steps::score(r.model, end.flights, end.truth, end.held, nullptr);
  kept.round = 2;
  kept.added = voltage;
  kept.look_alikes = {{drift, NAN}};  // as the round that kept the voltage lists it
  r.rounds.push_back(kept);
  ASSERT_EQ(r.model.slow_terms, (std::vector<std::string>{heater, voltage}));
  // Without slow look-alikes, a slow term keeps its name.
  LoopResult as_kept = r;
  DiagnoseOptions names_kept;
  names_kept.slow_look_alikes = false;
  const loop_steps::LoopContext kept_context{end.start, end.flights, end.truth, end.held,
                                             nullptr,   names_kept,  0.05};
  loop_steps::Round keep(kept_context, 3, &as_kept);
  EXPECT_FALSE(keep.better_look_alike_in_place());

  loop_steps::Round rename(end.context, 3, &r);
  ASSERT_TRUE(rename.better_look_alike_in_place());
  const LoopRound& after = r.rounds.back();
  ASSERT_EQ(after.replaced.size(), 1u);
  EXPECT_EQ(after.replaced[0].first, voltage);
  EXPECT_EQ(after.added, drift);
  EXPECT_EQ(r.model.slow_terms, (std::vector<std::string>{heater, drift}));
  const double tl_next_nT = end.next_nT(end.start);
  const double voltage_next_nT = end.next_nT(as_kept.model);
  const double drift_next_nT = end.next_nT(r.model);
  std::printf(
      "  held out %.4f -> %.4f nT (halves %.4f -> %.4f, %.4f -> %.4f); next flight TL %.3f, "
      "%s %.3f, %s %.3f nT\n",
      kept.heldout_std_nT, after.heldout_std_nT, kept.selection_std_nT, after.selection_std_nT,
      kept.confirmation_std_nT, after.confirmation_std_nT, tl_next_nT, voltage.c_str(),
      voltage_next_nT, drift.c_str(), drift_next_nT);
  // It lowers the held-out error by the accepted share, neither half rises, and the next
  // flight falls to well below TL.
  const DiagnoseOptions defaults;
  EXPECT_LE(std::pow(after.heldout_std_nT / kept.heldout_std_nT, 2),
            1.0 - defaults.accept_fraction);
  EXPECT_LE(after.selection_std_nT, kept.selection_std_nT);
  EXPECT_LE(after.confirmation_std_nT, kept.confirmation_std_nT);
  EXPECT_GT(voltage_next_nT, tl_next_nT);
  EXPECT_LT(drift_next_nT, 0.5 * tl_next_nT);
}

TEST(Discovery, ASlowTermsTimeConstantIsEstimatedAgainWithTheOtherTermsInPlace) {
  // Run 111, second aircraft, its states recorded: heaters of cur_strb (I², 60.5 s) and of
  // cur_srvo_o (I², 48.6 s), and a pick-up of cur_heat. The first round writes the strobes'
  // heater as field:cur_strb|lp(64.9), its time constant estimated while the other heater was
  // still in the residual; the pick-up follows and no term passes
  // (scripts/bench_discovery 1 111 half-several states draws=3 why). With every other term in
  // place, the calibration rows the slow stage sizes it on put its time constant at the truth's
  // within a percent, and the held-out lines and the next flight follow.
  const sim::Scenario base = base_with_states();
  std::vector<sim::HiddenEffect> effects;
  const sim::Scenario a = test::discovery_scenario(111, 3, base, 1, &effects);
  const sim::HiddenEffect* heater = drawn(effects, "thermal", "cur_strb");
  ASSERT_TRUE(heater) << "run 111 draws no heater of cur_strb";
  RoundAtTheEnd end(a, base_lambda(), {"dcurrent:cur_heat"});
  const std::string kept = "field:cur_strb|lp(64.9)";
  LoopResult r = end.with_slow_term(kept);
  const LoopRound before = r.rounds.back();
  const Model model_before = r.model;
  loop_steps::Round round(end.context, 3, &r);
  const auto at = std::find(r.model.terms.begin(), r.model.terms.end(), TermSpec(kept));
  ASSERT_NE(at, r.model.terms.end());
  const std::string retimed =
      round.retimed_slow_term(r.model, static_cast<size_t>(at - r.model.terms.begin()));
  double tau_s = NAN;
  ASSERT_EQ(std::sscanf(retimed.c_str(), "field:cur_strb|lp(%lf)", &tau_s), 1) << retimed;
  EXPECT_NEAR(tau_s, heater->time_constant_s, 0.01 * heater->time_constant_s);
  // The refinement writes it so, as a round of its own.
  ASSERT_TRUE(round.refine_parameters({}));
  const LoopRound& now = r.rounds.back();
  ASSERT_EQ(now.replaced.size(), 1u);
  EXPECT_EQ(now.replaced.front().first, kept);
  EXPECT_EQ(now.added, retimed);
  EXPECT_NE(std::find(r.model.slow_terms.begin(), r.model.slow_terms.end(), retimed),
            r.model.slow_terms.end());
  const double next_before_nT = end.next_nT(model_before);
  const double next_now_nT = end.next_nT(r.model);
  std::printf(
      "  %s -> %s: calibration rows %.4f -> %.4f nT, held out %.4f -> %.4f nT, next "
      "flight %.3f -> %.3f nT\n",
      kept.c_str(), retimed.c_str(), before.calibration_std_nT, now.calibration_std_nT,
      before.heldout_std_nT, now.heldout_std_nT, next_before_nT, next_now_nT);
  EXPECT_LT(now.calibration_std_nT, before.calibration_std_nT);
  EXPECT_LT(std::pow(now.heldout_std_nT / before.heldout_std_nT, 2), 0.5);
  EXPECT_LT(next_now_nT, 0.8 * next_before_nT);
}

TEST(Discovery, AKeptSlowTermIsWrittenAsTheBodyFixedFieldWhereThatDoesBetter) {
  // Run 169, second aircraft, its states recorded: an inductive pick-up of cur_srvo_o and a
  // 464 s heater of cur_ac_hi (a body-fixed field). With fit.lambda 1e-4 the loop's second round
  // keeps the heater as a reading added to the scalar, scalar:cur_ac_hi|lp(588); a later round
  // lowers fit.lambda to 1e-5 and no new term passes: kept so, the model leaves 0.540 nT on the
  // next flight against the oracle's 0.132 (scripts/bench_discovery 1 169 half-several states
  // draws=3 why).
  // With every other term in place, the same signal projected on the Earth's field does better on
  // both halves of the held-out lines, and the next flight follows.
  const sim::Scenario base = base_with_states();
  std::vector<sim::HiddenEffect> effects;
  const sim::Scenario a = test::discovery_scenario(169, 2, base, 1, &effects);
  ASSERT_TRUE(drawn(effects, "thermal", "cur_ac_hi")) << "run 169 draws no heater of cur_ac_hi";
  RoundAtTheEnd end(a, 1e-5, {"dcurrent:cur_srvo_o"});
  const std::string kept = "scalar:cur_ac_hi|lp(588)", field = "field:cur_ac_hi|lp(588)";
  LoopResult r = end.with_slow_term(kept);
  const LoopRound before = r.rounds.back();
  const Model model_before = r.model;
  loop_steps::Round round(end.context, 4, &r);
  ASSERT_TRUE(round.refine_parameters({}));
  const LoopRound& now = r.rounds.back();
  ASSERT_EQ(now.replaced.size(), 1u);
  EXPECT_EQ(now.replaced.front().first, kept);
  EXPECT_NE(now.replaced.front().second.find("body-fixed field"), std::string::npos)
      << now.replaced.front().second;
  EXPECT_EQ(now.added, field);
  EXPECT_NE(std::find(r.model.slow_terms.begin(), r.model.slow_terms.end(), field),
            r.model.slow_terms.end());
  const double next_before_nT = end.next_nT(model_before);
  const double next_now_nT = end.next_nT(r.model);
  std::printf(
      "  %s -> %s: held out %.4f -> %.4f nT (halves %.4f -> %.4f, %.4f -> %.4f), next "
      "flight %.3f -> %.3f nT\n",
      kept.c_str(), now.added.c_str(), before.heldout_std_nT, now.heldout_std_nT,
      before.selection_std_nT, now.selection_std_nT, before.confirmation_std_nT,
      now.confirmation_std_nT, next_before_nT, next_now_nT);
  EXPECT_LT(now.selection_std_nT, before.selection_std_nT);
  EXPECT_LT(now.confirmation_std_nT, before.confirmation_std_nT);
  EXPECT_LT(next_now_nT, 0.7 * next_before_nT);
  // Written so, the scalar reading does not come back in its place.
  loop_steps::Round again(end.context, 5, &r);
  if (again.refine_parameters({})) {
    for (const auto& [from, why] : r.rounds.back().replaced)
      EXPECT_EQ(r.rounds.back().added.find("scalar:cur_ac_hi"), std::string::npos) << from;
  }
}

TEST(Discovery, AReferenceFitsHeaterIsSizedOnTheLinesAndThenRetimed) {
  // Run 169, third aircraft, its states recorded: an inductive pick-up of cur_srvo_o and a
  // 464 s heater of cur_ac_hi. Once TL is written as the exact norm (fit.method reference,
  // fit.lambda 1e-6), the loop keeps the heater as field:cur_ac_hi|abs|lp(303), sized on the
  // calibration rows, where cur_ac_hi does not switch, then a stand-in, field:cur_ac_lo|play;
  // kept so, the model leaves 0.800 nT on the next flight against the oracle's 0.098
  // (scripts/bench_discovery 1 169 half-several states draws=3 why).
  // Sized by the slow stage on the calibration rows and the lines beside them, the heater lowers
  // the held-out error on both halves; the stand-in becomes redundant, and the time constant,
  // estimated again where the lines size it, comes back to the heater's.
  const sim::Scenario base = base_with_states();
  std::vector<sim::HiddenEffect> effects;
  const sim::Scenario a = test::discovery_scenario(169, 2, base, 2, &effects);
  const sim::HiddenEffect* heater = drawn(effects, "thermal", "cur_ac_hi");
  ASSERT_TRUE(heater) << "run 169 draws no heater of cur_ac_hi";
  RoundAtTheEnd end(a, 1e-4, {});
  const std::string kept = "field:cur_ac_hi|abs|lp(303)";
  const Model m = end.exact_norm_with(
      {"dcurrent:cur_srvo_o", "bias", "norm", kept, "field:cur_ac_lo|play(0.641)"});
  LoopResult& r = end.r;
  r.model = m;
  r.rounds.push_back(loop_steps::score(m, end.flights, end.truth, end.held, nullptr));
  const LoopRound before = r.rounds.back();
  const Model model_before = r.model;
  loop_steps::Round round(end.context, 4, &r);
  ASSERT_TRUE(round.refine_parameters({}));
  const LoopRound moved = r.rounds.back();
  ASSERT_EQ(moved.replaced.size(), 1u);
  EXPECT_EQ(moved.replaced.front().first, kept);
  EXPECT_NE(moved.replaced.front().second.find("lines beside them"), std::string::npos)
      << moved.replaced.front().second;
  EXPECT_NE(std::find(r.model.slow_terms.begin(), r.model.slow_terms.end(), kept),
            r.model.slow_terms.end());
  EXPECT_FALSE(r.model.fit.slow_lines.empty());
  EXPECT_LT(moved.selection_std_nT, before.selection_std_nT);
  EXPECT_LT(moved.confirmation_std_nT, before.confirmation_std_nT);
  // The time constant estimated again on the rows the slow stage now sizes it on.
  round.backward_pass();
  loop_steps::Round again(end.context, 5, &r);
  ASSERT_TRUE(again.refine_parameters({}));
  const LoopRound& now = r.rounds.back();
  const TermSpec* retimed = nullptr;
  for (const TermSpec& t : r.model.terms)
    if (t.text().rfind("field:cur_ac_hi|", 0) == 0) retimed = &t;
  ASSERT_TRUE(retimed) << now.added;
  double tau_s = NAN;
  for (const Transform& x : retimed->expr()->signal().transforms)
    if (x.kind == TransformKind::LowPass) tau_s = x.param;
  const double next_before_nT = end.next_nT(model_before);
  const double next_now_nT = end.next_nT(r.model);
  std::printf(
      "  %s: held out %.4f -> %.4f (on the lines) -> %.4f nT as %s (heater %.0f s); next flight "
      "%.3f -> %.3f nT\n",
      kept.c_str(), before.heldout_std_nT, moved.heldout_std_nT, now.heldout_std_nT,
      retimed->text().c_str(), heater->time_constant_s, next_before_nT, next_now_nT);
  EXPECT_NEAR(std::log(tau_s / heater->time_constant_s), 0.0, std::log(1.15));
  EXPECT_LT(now.heldout_std_nT, 0.2 * before.heldout_std_nT);
  EXPECT_LT(next_now_nT, 0.2 * next_before_nT);
  for (const TermSpec& t : r.model.terms)
    EXPECT_NE(t.text().rfind("field:cur_ac_lo", 0), 0u) << "the stand-in stays: " << t.text();
}

TEST(Discovery, ARetimedSlowTermNeedsNoResolutionOnTheLines) {
  // Run 111, first aircraft, its states recorded: heaters of cur_strb (I², 60.5 s) and of
  // cur_srvo_o (I², 48.6 s), and a pick-up of cur_heat. The loop writes the strobes' heater as
  // field:cur_strb|lp(63.2) and the pick-up (scripts/bench_discovery 1 111 half-several states
  // draws=3 why). With both in place the calibration rows put the time constant at 59.8 s; the
  // held-out lines confirm it on both halves by more than the accepted share of their variance,
  // by less than the 0.03 nT a new channel must gain there: the lines did not choose it
  // (Round::improves_in_place).
  const sim::Scenario base = base_with_states();
  std::vector<sim::HiddenEffect> effects;
  const sim::Scenario a = test::discovery_scenario(111, 3, base, 0, &effects);
  const sim::HiddenEffect* heater = drawn(effects, "thermal", "cur_strb");
  ASSERT_TRUE(heater) << "run 111 draws no heater of cur_strb";
  RoundAtTheEnd end(a, base_lambda(), {"dcurrent:cur_heat"});
  const std::string kept = "field:cur_strb|lp(63.2)";
  LoopResult r = end.with_slow_term(kept);
  const LoopRound before = r.rounds.back();
  const Model model_before = r.model;
  loop_steps::Round round(end.context, 3, &r);
  ASSERT_TRUE(round.refine_parameters({}));
  const LoopRound& now = r.rounds.back();
  ASSERT_EQ(now.replaced.size(), 1u);
  EXPECT_EQ(now.replaced.front().first, kept);
  double tau_s = NAN;
  ASSERT_EQ(std::sscanf(now.added.c_str(), "field:cur_strb|lp(%lf)", &tau_s), 1) << now.added;
  const double next_before_nT = end.next_nT(model_before);
  const double next_now_nT = end.next_nT(r.model);
  std::printf(
      "  %s -> %s: held out %.4f (%.4f, %.4f) -> %.4f (%.4f, %.4f) nT, next flight %.3f "
      "-> %.3f nT\n",
      kept.c_str(), now.added.c_str(), before.heldout_std_nT, before.selection_std_nT,
      before.confirmation_std_nT, now.heldout_std_nT, now.selection_std_nT, now.confirmation_std_nT,
      next_before_nT, next_now_nT);
  EXPECT_NEAR(tau_s, heater->time_constant_s, 0.03 * heater->time_constant_s);
  // Under the resolution on the lines, above the accepted share on each half.
  EXPECT_LT(before.heldout_std_nT - now.heldout_std_nT, DiagnoseOptions{}.resolution_nT);
  EXPECT_GE(loop_steps::variance_share(now.selection_std_nT, before.selection_std_nT),
            DiagnoseOptions{}.accept_fraction);
  EXPECT_GE(loop_steps::variance_share(now.confirmation_std_nT, before.confirmation_std_nT),
            DiagnoseOptions{}.accept_fraction);
  EXPECT_LT(next_now_nT, 0.9 * next_before_nT);
}

TEST(Discovery, AnIntegralOfACurrentThatNeverReversesIsAClock) {
  // Run 198's third aircraft (a hysteresis of cur_outpwr) ended with field:cur_flap|int|lp(1.47):
  // the flap motor's current is on for bursts and never reverses, so its integral rises through
  // the flight, a clock that fitted what drifted on the first flight and read 7.45 nT on the next
  // (TL 0.24). Every load of the simulated aircraft is such a current; a current driven both
  // ways integrates to a position within its range.
  const sim::Simulation s = sim::simulate(base_with_states(), Igrf::installed());
  FlightData f = s.flight;
  using diagnose_search::integral_in_time;
  for (const char* load : {"cur_flap", "cur_tank", "cur_strb", "cur_heat", "cur_com_1"}) {
    EXPECT_TRUE(integral_in_time(parse_signal(std::string(load) + "|int", "t"), f)) << load;
    EXPECT_TRUE(integral_in_time(parse_signal(std::string(load) + "|int|lp(1.47)", "t"), f))
        << load;
  }
  // A motor driven out and back: +2 A for 20 s, then -2 A for 20 s, every 100 s.
  const Eigen::VectorXd t = f.tt();
  Eigen::VectorXd both(t.size());
  for (Eigen::Index i = 0; i < t.size(); ++i) {
    const double phase = std::fmod(t[i] - t[0], 100.0);
    both[i] = phase < 20 ? 2.0 : phase < 40 ? -2.0 : 0.0;
  }
  f.set("cur_motor", both);
  EXPECT_FALSE(integral_in_time(parse_signal("cur_motor|int", "t"), f));
  // No integral: not judged.
  EXPECT_FALSE(integral_in_time(parse_signal("cur_flap|lp(1.47)", "t"), f));
}

TEST(Discovery, AStepOfAChannelThatCrossesItsThresholdOnceIsAStepInTime) {
  // The simulated aircraft's battery charge currents decay through every level once
  // (2 A e^(-t/1800 s) and 0.9 of it, 0.02 A of noise); its loads cycle. A step of a battery
  // current is a step in time, which fits whatever changed at that moment (the loop wrote
  // field:cur_bat_2|step(1.75) beside the true terms of run 129's first aircraft and
  // field:cur_bat_1|step(1.76) beside run 119's); a relay of a load is not.
  const sim::Simulation s = sim::simulate(base_with_states(), Igrf::installed());
  const FlightData& f = s.flight;
  const auto median = [&](const std::string& channel) {
    std::vector<double> v = signal_values_sorted(parse_signal(channel, "t"), f);
    return v[v.size() / 2];
  };
  using diagnose_search::step_in_time;
  for (const char* battery : {"cur_bat_1", "cur_bat_2"}) {
    EXPECT_TRUE(
        step_in_time(parse_signal(std::string(battery) + "|step(?)", "t"), median(battery), f))
        << battery;
    // Near its start too: 1.75 A is crossed about 30 s into the flight.
    EXPECT_TRUE(step_in_time(parse_signal(std::string(battery) + "|step(?)", "t"), 1.75, f))
        << battery;
  }
  EXPECT_TRUE(step_in_time(parse_signal("cur_bat_1|step(?)", "t"), 1.76, f));
  for (const char* load : {"cur_tank", "cur_strb", "cur_srvo_i", "cur_heat", "cur_com_1"})
    EXPECT_FALSE(step_in_time(parse_signal(std::string(load) + "|step(?)", "t"), median(load), f))
        << load;
  EXPECT_FALSE(step_in_time(parse_signal("cur_tank|step(?)", "t"), 1.25, f));
  EXPECT_FALSE(step_in_time(parse_signal("cur_srvo_i|step(?)", "t"), 0.3074, f));
  // A step after another transform is not judged.
  EXPECT_FALSE(step_in_time(parse_signal("cur_bat_1|abs|step(?)", "t"), 1.76, f));
}

TEST(Discovery, ARelayChatteringOnItsControlsNoiseIsNoStepInTime) {
  // Run 184, second aircraft (scripts/bench_discovery 1 184 half-several states draws=3): a relay
  // of cur_com_1 above 0.399 A, within the noise of the 0.4 A the current idles at, so the relay
  // is on in about half the samples all through the flight. Its 30 s majority wanders about one
  // half and changes in bursts, which once read as a single switch in time and dropped the step
  // from the search (the loop then stopped at 0.85 nT on the next flight, the oracle 0.03).
  std::vector<sim::HiddenEffect> effects;
  const sim::Scenario a = test::discovery_scenario(184, 1, base_with_states(), 1, &effects);
  const sim::HiddenEffect* relay = drawn(effects, "relay", "cur_com_1");
  ASSERT_TRUE(relay) << "run 184 draws no relay of cur_com_1";
  const sim::Simulation fa = sim::simulate(a, Igrf::installed());
  const std::vector<double> values =
      signal_values_sorted(parse_signal("cur_com_1", "t"), fa.flight);
  const double on_share =
      static_cast<double>(values.end() -
                          std::upper_bound(values.begin(), values.end(), relay->threshold)) /
      static_cast<double>(values.size());
  std::printf("  relay above %.4f A: on in %.1f %% of the samples\n", relay->threshold,
              100 * on_share);
  ASSERT_GT(on_share, 0.3);
  ASSERT_LT(on_share, 0.7);
  EXPECT_FALSE(diagnose_search::step_in_time(parse_signal("cur_com_1|step(?)", "t"),
                                             relay->threshold, fa.flight));
  Model start = load_model_yaml(test::source_dir() + "/config/models/tl_sim.yaml");
  fit_model(start, {&fa.flight});
  const Diagnosis dx = diagnose(start, fa.flight, "mag_1_c");
  ASSERT_FALSE(dx.candidates.empty());
  const Candidate& top = dx.candidates.front();
  std::printf("  top: %s, held out %.3f -> %.3f nT\n", top.term.text().c_str(), dx.baseline_std_nT,
              top.std_after_nT);
  EXPECT_EQ(top.term.text().rfind("field:cur_com_1|step(", 0), 0u) << top.term.text();
  EXPECT_TRUE(top.accepted);
  EXPECT_LT(top.std_after_nT, 0.2 * dx.baseline_std_nT);
}

TEST(Discovery, ABandPassTermSlowerThanTheBandIsSizedByTheSlowStage) {
  // Run 111, first aircraft, its states recorded: heaters of cur_strb (I^2, 60.5 s) and of
  // cur_srvo_o (I^2, 48.6 s), and a pick-up of cur_heat. The loop's first round writes the
  // strobes' heater as field:cur_strb|lp(63.2) sized by the band-pass: on the held-out lines its
  // band-pass form leaves 0.4515 nT and its slow-stage form 0.4526 nT, while the calibration
  // box, which the band-pass sees only through what its band passes of a 63 s low-pass, keeps
  // 0.5 nT of it (scripts/bench_discovery 1 111 half-several states draws=3 why). With the
  // pick-up in place, the same term sized by the slow stage on the calibration rows, unfiltered,
  // takes the band-pass form's place (Round::refine_parameters, moves_to_slow_stage).
  const sim::Scenario base = base_with_states();
  std::vector<sim::HiddenEffect> effects;
  const sim::Scenario a = test::discovery_scenario(111, 3, base, 0, &effects);
  ASSERT_TRUE(drawn(effects, "thermal", "cur_strb")) << "run 111 draws no heater of cur_strb";
  const std::string kept = "field:cur_strb|lp(63.2)";
  RoundAtTheEnd end(a, base_lambda(), {kept, "dcurrent:cur_heat"});
  LoopResult r = end.r;
  ASSERT_TRUE(r.model.slow_terms.empty());
  const LoopRound before = r.rounds.back();
  const Model model_before = r.model;
  loop_steps::Round round(end.context, 3, &r);
  ASSERT_TRUE(round.refine_parameters({}));
  const LoopRound& now = r.rounds.back();
  ASSERT_EQ(now.replaced.size(), 1u);
  EXPECT_EQ(now.replaced.front().first, kept);
  EXPECT_NE(now.replaced.front().second.find("slow stage"), std::string::npos)
      << now.replaced.front().second;
  EXPECT_EQ(now.added, kept);
  EXPECT_EQ(r.model.slow_terms, std::vector<std::string>{kept});
  const double next_before_nT = end.next_nT(model_before);
  const double next_now_nT = end.next_nT(r.model);
  std::printf(
      "  %s to the slow stage: calibration rows %.4f -> %.4f nT, held out %.4f (%.4f, %.4f) -> "
      "%.4f (%.4f, %.4f) nT, next flight %.3f -> %.3f nT\n",
      kept.c_str(), before.calibration_std_nT, now.calibration_std_nT, before.heldout_std_nT,
      before.selection_std_nT, before.confirmation_std_nT, now.heldout_std_nT, now.selection_std_nT,
      now.confirmation_std_nT, next_before_nT, next_now_nT);
  // The calibration rows show it: their variance falls by more than half.
  EXPECT_LT(std::pow(now.calibration_std_nT / before.calibration_std_nT, 2), 0.5);
  EXPECT_GE(loop_steps::variance_share(now.heldout_std_nT, before.heldout_std_nT),
            DiagnoseOptions{}.accept_fraction);
  EXPECT_LT(next_now_nT, 0.7 * next_before_nT);
}

TEST(Discovery, AKeptTermGivesWayToALookAlikeThatDoesBetterWithTheOtherTermsInPlace) {
  // Run 113, first aircraft, its states recorded: a flex of the yaw rate (3.5 s) and an inductive
  // pick-up of cur_bat_2. The loop's first round keeps a pair, dcurrent:cur_bat_2 and
  // field:ins_acc_y|lp(3.34): the lateral acceleration is the yaw rate times the airspeed, which
  // the flight holds within about one percent, and a pair's terms were never compared with their
  // look-alikes (scripts/bench_discovery 1 113 half-several states draws=3 why). With the pick-up
  // written, the yaw rate's own term leaves less on the held-out lines, and takes the place.
  const sim::Scenario base = base_with_states();
  std::vector<sim::HiddenEffect> effects;
  const sim::Scenario a = test::discovery_scenario(113, 2, base, 0, &effects);
  ASSERT_TRUE(drawn(effects, "flex", "yaw_rate")) << "run 113 draws no flex of the yaw rate";
  ASSERT_TRUE(drawn(effects, "inductive", "cur_bat_2")) << "run 113 draws no pick-up of cur_bat_2";
  const std::string acc = "field:ins_acc_y|lp(3.34)", yaw = "field:yaw_rate|lp(3.34)";
  RoundAtTheEnd end(a, base_lambda(), {"dcurrent:cur_bat_2", acc});
  // The look-alikes: the same term through each channel that moves with its own.
  {
    loop_steps::Round round(end.context, 2, &end.r);
    const std::set<std::string> fields = {"cur_bat_2", "ins_acc_y"};
    const std::vector<std::string> of_acc = round.look_alikes_of(TermSpec(acc), fields);
    EXPECT_NE(std::find(of_acc.begin(), of_acc.end(), yaw), of_acc.end());
    const std::vector<std::string> of_bat =
        round.look_alikes_of(TermSpec("dcurrent:cur_bat_2"), fields);
    EXPECT_NE(std::find(of_bat.begin(), of_bat.end(), "dcurrent:cur_bat_1"), of_bat.end());
    for (const std::string& t : of_acc) EXPECT_EQ(t.find("cur_bat"), std::string::npos) << t;
  }
  const double before_nT = end.r.rounds.back().heldout_std_nT;
  loop_steps::Round round(end.context, 2, &end.r);
  ASSERT_TRUE(round.better_look_alike_in_place());
  const LoopRound& swapped = end.r.rounds.back();
  EXPECT_EQ(swapped.added, yaw);
  ASSERT_EQ(swapped.replaced.size(), 1u);
  EXPECT_EQ(swapped.replaced[0].first, acc);
  EXPECT_LT(swapped.heldout_std_nT, before_nT);
  EXPECT_EQ(std::count(end.r.model.terms.begin(), end.r.model.terms.end(), TermSpec(yaw)), 1);
  EXPECT_EQ(std::count(end.r.model.terms.begin(), end.r.model.terms.end(), TermSpec(acc)), 0);
  std::printf("  %s -> %s: held out %.4f -> %.4f nT\n", acc.c_str(), yaw.c_str(), before_nT,
              swapped.heldout_std_nT);
  // From the true terms, nothing gives way: neither the yaw rate to the acceleration nor the
  // pick-up to the other battery's.
  loop_steps::Round again(end.context, 3, &end.r);
  EXPECT_FALSE(again.better_look_alike_in_place()) << end.r.rounds.back().added;
}

TEST(Discovery, ALookAlikeThatOnlyTiesTheKeptTermLeavesItsNameInPlace) {
  // Run 148, first aircraft, its states recorded: a flex of the pitch rate. The loop's round keeps
  // rate:pitch_rate and lists field:ins_pitch|d beside it: the simulator's pitch rate is the
  // attitude's derivative, and the two leave the same held-out error to four digits
  // (scripts/bench_discovery 1 148 half-several states draws=3 why). A swap renames the effect,
  // so a tie keeps the recorded rate the round chose; a look-alike that does better by the
  // accepted share on both halves takes the place (the test above).
  const sim::Scenario base = base_with_states();
  std::vector<sim::HiddenEffect> effects;
  const sim::Scenario a = test::discovery_scenario(148, 1, base, 0, &effects);
  ASSERT_TRUE(drawn(effects, "flex", "pitch_rate")) << "run 148 draws no flex of the pitch rate";
  const std::string rate = "rate:pitch_rate", alike = "field:ins_pitch|d";
  RoundAtTheEnd end(a, base_lambda(), {rate, "bias", "norm"});
  end.r.rounds.back().added = rate;
  // The look-alike the round listed, fitted in the rate's place: a tie.
  end.r.rounds.back().look_alikes = {{alike, end.r.rounds.back().heldout_std_nT}};
  const LoopRound now = end.r.rounds.back();
  Model swapped = end.start;
  for (const char* t : {alike.c_str(), "bias", "norm"}) swapped.add_term(TermSpec(t));
  fit_model(swapped, end.flights);
  const LoopRound tie = loop_steps::score(swapped, end.flights, end.truth, end.held, nullptr);
  std::printf("  %s %.5f nT held out (halves %.5f, %.5f), %s %.5f (halves %.5f, %.5f)\n",
              rate.c_str(), now.heldout_std_nT, now.selection_std_nT, now.confirmation_std_nT,
              alike.c_str(), tie.heldout_std_nT, tie.selection_std_nT, tie.confirmation_std_nT);
  EXPECT_LT(loop_steps::variance_share(tie.heldout_std_nT, now.heldout_std_nT),
            DiagnoseOptions{}.accept_fraction);
  loop_steps::Round round(end.context, 2, &end.r);
  const std::vector<std::string> listed =
      round.look_alikes_of(TermSpec(rate), std::set<std::string>{"pitch_rate"});
  ASSERT_NE(std::find(listed.begin(), listed.end(), alike), listed.end());
  EXPECT_FALSE(round.better_look_alike_in_place()) << end.r.rounds.back().added;
  EXPECT_EQ(std::count(end.r.model.terms.begin(), end.r.model.terms.end(), TermSpec(rate)), 1);
}

TEST(Discovery, ATermAnotherMakesRedundantOnceItsParametersAreEstimatedAgainLeaves) {
  // Run 113, second aircraft, its states recorded: a flex of the yaw rate (3.5 s) and an
  // inductive pick-up of cur_bat_2. The loop's first round keeps the pick-up with the yaw rate
  // through a 3.28 s low-pass (estimated while the residual still held TL's expansion), and a
  // later round adds the lateral acceleration (the yaw rate times the airspeed) through 3.84 s:
  // the two low-passes together write the 3.5 s one. No refit of the kept terms with the
  // acceleration in place gains what a change must, and the loop ended "complete" with a channel
  // more (scripts/bench_discovery 1 113 half-several states draws=3 why keep-redundant). With the
  // yaw rate's time constant estimated again without it, the acceleration is redundant (and
  // the other way round: either, its time constant estimated again, writes the flex).
  const sim::Scenario base = base_with_states();
  std::vector<sim::HiddenEffect> effects;
  const sim::Scenario a = test::discovery_scenario(113, 2, base, 1, &effects);
  const sim::HiddenEffect* flex = drawn(effects, "flex", "yaw_rate");
  ASSERT_TRUE(flex) << "run 113 draws no flex of the yaw rate";
  const std::string yaw = "field:yaw_rate|lp(3.28)", acc = "field:ins_acc_y|lp(3.84)";
  RoundAtTheEnd end(a, base_lambda(), {"dcurrent:cur_bat_2", yaw, acc});
  const double before_nT = end.r.rounds.back().heldout_std_nT;
  const double next_before_nT = end.next_nT(end.r.model);
  std::set<std::string> dropped;
  loop_steps::Round round(end.context, 3, &end.r);
  ASSERT_TRUE(round.redundant_once_refined(&dropped));
  const LoopRound& last = end.r.rounds.back();
  // One of the two leaves; the other, its time constant estimated again, is the flex's own.
  ASSERT_EQ(last.removed.size(), 1u);
  ASSERT_EQ(last.replaced.size(), 1u);
  const std::set<std::string> pair = {last.removed[0].first, last.replaced[0].first};
  EXPECT_EQ(pair, (std::set<std::string>{yaw, acc}));
  EXPECT_TRUE(dropped.count(last.removed[0].first));
  const TermSpec kept(last.added);
  ASSERT_TRUE(kept.expr()) << last.added;
  const SignalExpr& signal = kept.expr()->signal();
  ASSERT_EQ(signal.sources.size(), 1u);
  ASSERT_EQ(signal.transforms.size(), 1u);
  EXPECT_NEAR(signal.transforms[0].param, flex->time_constant_s, 0.05 * flex->time_constant_s);
  const double dropped_nT = last.heldout_std_nT;
  // Which of the two stays is the held-out lines' choice (here, the model built directly with
  // TL's band-pass fit, the acceleration; in the loop, with TL as the exact norm, the yaw rate,
  // and the look-alike pass names the other when it does better): one term writes the flex.
  int flex_terms = 0;
  for (const TermSpec& t : end.r.model.terms) {
    const std::set<std::string> f = loop_steps::fields_of(t);
    flex_terms += static_cast<int>(f.count("yaw_rate") + f.count("ins_acc_y"));
  }
  EXPECT_EQ(flex_terms, 1);
  // Without the acceleration the lines lose less than a term must gain, and the next flight no
  // more than that.
  const DiagnoseOptions defaults;
  EXPECT_LT(dropped_nT, before_nT + defaults.resolution_nT);
  EXPECT_LT(end.r.rounds.back().heldout_std_nT, before_nT + defaults.resolution_nT);
  const double next_after_nT = end.next_nT(end.r.model);
  EXPECT_LT(next_after_nT, next_before_nT + defaults.resolution_nT);
  std::printf("  %s + %s -> %s: held out %.4f -> %.4f nT, next flight %.4f -> %.4f nT\n",
              yaw.c_str(), acc.c_str(), end.r.rounds.back().added.c_str(), before_nT,
              end.r.rounds.back().heldout_std_nT, next_before_nT, next_after_nT);
  // From the true terms, nothing leaves: the pick-up is needed with the flex's time constant
  // estimated again, and the flex with nothing to estimate but its own.
  loop_steps::Round again(end.context, 5, &end.r);
  EXPECT_FALSE(again.redundant_once_refined(&dropped)) << end.r.rounds.back().added;
}

TEST(DiscoveryLong, AThresholdEstimatedBeforeTheOtherTermsIsEstimatedAgainWithThem) {
  // Run 101, second aircraft, its states recorded: a relay of cur_outpwr above 13.9 A and a
  // product yaw_rate*vol_outpwr. The loop's first round takes the relay's step together with
  // field:ins_acc_y (which moves with the yaw rate), its threshold estimated at 14 A at the
  // model's ridge; the ridge then falls to 1e-6 and no term passes (scripts/bench_discovery 1 101
  // half-several states draws=2 no-refine). The threshold estimated again with the other terms
  // in place is the relay's own, and the held-out error falls by far more than a term must gain.
  const sim::Scenario base = base_with_states();
  std::vector<sim::HiddenEffect> effects;
  const sim::Scenario a = test::discovery_scenario(101, 2, base, 1, &effects);
  const sim::HiddenEffect* relay = drawn(effects, "relay", "cur_outpwr");
  ASSERT_TRUE(relay) << "run 101 draws no relay of cur_outpwr";
  const double threshold = relay->threshold;
  RoundAtTheEnd end(a, 1e-6, {"field:cur_outpwr|step(14)", "field:ins_acc_y"});
  const sim::Simulation& fb = end.fb;
  const Model& model = end.model;
  LoopResult& r = end.r;
  const loop_steps::LoopContext& context = end.context;
  loop_steps::Round round(context, 3, &r);
  ASSERT_TRUE(round.refine_parameters({}));
  ASSERT_EQ(r.rounds.size(), 2u);
  const LoopRound& lr = r.rounds.back();
  ASSERT_EQ(lr.replaced.size(), 1u);
  EXPECT_EQ(lr.replaced[0].first, "field:cur_outpwr|step(14)");
  const auto e = parse_expr_term(lr.added);
  ASSERT_TRUE(e) << lr.added;
  const double estimated = e->parameters().at(0).second;
  const double before_nT = r.rounds[0].heldout_std_nT, after_nT = lr.heldout_std_nT;
  const double next_before_nT = evaluate_model(model, fb.flight, "mag_1_c", false).std_nT;
  const double next_after_nT = evaluate_model(r.model, fb.flight, "mag_1_c", false).std_nT;
  std::printf(
      "  relay above %.4f A: %s -> %s; held out %.4f -> %.4f nT, next flight %.3f -> %.3f nT\n",
      threshold, lr.replaced[0].first.c_str(), lr.added.c_str(), before_nT, after_nT,
      next_before_nT, next_after_nT);
  EXPECT_NEAR(estimated, threshold, 0.03);
  EXPECT_LT(after_nT, 0.7 * before_nT);
  EXPECT_LT(next_after_nT, 0.6 * next_before_nT);
  EXPECT_LE(lr.selection_std_nT, r.rounds[0].selection_std_nT);
  EXPECT_LE(lr.confirmation_std_nT, r.rounds[0].confirmation_std_nT);
  // Estimated again with the model it now has, nothing moves by what a term must gain.
  loop_steps::Round again(context, 4, &r);
  EXPECT_FALSE(again.refine_parameters({}));
}

TEST(Discovery, AThresholdIsPlacedWhereTheHeldOutLinesCrossIt) {
  // Run 101, second aircraft (the relay of cur_outpwr above 13.885 A and the product
  // yaw_rate*vol_outpwr; the model the loop reaches, scripts/bench_discovery 1 101 half-several
  // states draws=3 thresholds-on-calibration): the relay's step written at 13.951 A beside
  // field:ins_acc_y. The first flight's calibration lines hold 2 samples of cur_outpwr between
  // the two thresholds, its held-out lines 35, the next flight 193: the calibration rows cannot
  // tell the thresholds apart, the held-out lines can. The model without the step, diagnosed
  // again, ranks the same switch with the threshold its selection lines pin
  // (Search::threshold_on_selection); the refinement takes it without the resolution a new
  // channel needs (the gain sits in few samples, each far off).
  const sim::Scenario base = base_with_states();
  std::vector<sim::HiddenEffect> effects;
  const sim::Scenario a = test::discovery_scenario(101, 2, base, 1, &effects);
  const sim::HiddenEffect* relay = drawn(effects, "relay", "cur_outpwr");
  ASSERT_TRUE(relay) << "run 101 draws no relay of cur_outpwr";
  RoundAtTheEnd end(a, 1e-6, {"field:cur_outpwr|step(13.951)", "field:ins_acc_y"});
  const std::vector<double> next_values =
      signal_values_sorted(parse_signal("cur_outpwr", "t"), end.fb.flight);
  // The next flight's samples between a threshold and the relay's own.
  const auto between = [&](double x) {
    const double lo = std::min(x, relay->threshold), hi = std::max(x, relay->threshold);
    return std::upper_bound(next_values.begin(), next_values.end(), hi) -
           std::upper_bound(next_values.begin(), next_values.end(), lo);
  };
  const double before_nT = end.r.rounds[0].heldout_std_nT;
  const double next_before_nT = end.next_nT(end.model);
  // Placed by the calibration rows alone: nothing moves, or not to the relay's threshold.
  DiagnoseOptions calibration_only;
  calibration_only.place_thresholds_again = false;
  const loop_steps::LoopContext by_rows{end.start, end.flights,      end.truth, end.held,
                                        nullptr,   calibration_only, 0.05};
  LoopResult rows_r = end.r;
  loop_steps::Round by_rows_round(by_rows, 3, &rows_r);
  const bool rows_moved = by_rows_round.refine_parameters({});
  const double next_rows_nT = end.next_nT(rows_r.model);
  std::string rows_step = "unchanged";
  for (const TermSpec& t : rows_r.model.terms)
    if (rows_moved && t.text().rfind("field:cur_outpwr|step(", 0) == 0) rows_step = t.text();
  // Placed by the held-out lines.
  LoopResult& r = end.r;
  loop_steps::Round round(end.context, 3, &r);
  ASSERT_TRUE(round.refine_parameters({}));
  const LoopRound& lr = r.rounds.back();
  ASSERT_EQ(lr.replaced.size(), 1u);
  EXPECT_EQ(lr.replaced[0].first, "field:cur_outpwr|step(13.951)");
  EXPECT_NE(lr.replaced[0].second.find("threshold placed again"), std::string::npos)
      << lr.replaced[0].second;
  const auto e = parse_expr_term(lr.added);
  ASSERT_TRUE(e) << lr.added;
  const double placed = e->parameters().at(0).second;
  const double next_after_nT = end.next_nT(r.model);
  std::printf(
      "  relay above %.4f A (next flight: %ld samples below 13.951): by the calibration rows %s "
      "(next flight %.3f nT); by the held-out lines %s (%ld samples off): held out %.4f -> "
      "%.4f nT, next flight %.3f -> %.3f nT\n",
      relay->threshold, static_cast<long>(between(13.951)), rows_step.c_str(), next_rows_nT,
      lr.added.c_str(), static_cast<long>(between(placed)), before_nT, lr.heldout_std_nT,
      next_before_nT, next_after_nT);
  EXPECT_LT(between(placed), between(13.951) / 10);
  EXPECT_LT(lr.heldout_std_nT, before_nT);
  EXPECT_LE(lr.selection_std_nT, r.rounds[0].selection_std_nT);
  EXPECT_LE(lr.confirmation_std_nT, r.rounds[0].confirmation_std_nT);
  EXPECT_LT(next_after_nT, 0.6 * next_before_nT);
  EXPECT_LT(next_after_nT, 0.6 * next_rows_nT);
}

TEST(Discovery, AKeptTermsParametersAreEstimatedAgainBesideANewTerm) {
  // Run 117, second aircraft: a flex of roll_rate through 0.825 s and a 0.271 s scalar lag. The
  // first round takes scalar:roll_rate|lp(2.72) (its time constant stretched over the lag), the
  // second second_order; then the lag makes the confirmation lines worse (-37 %) and the loop
  // stopped at 2.57 nT held out, 3.10 nT on the next flight (scripts/bench_discovery 1 117
  // half-several states draws=2 no-refine). Neither the lag alone nor the flex's time constant
  // estimated again alone passes; the lag beside it with the time constant free does.
  const sim::Scenario base = base_with_states();
  std::vector<sim::HiddenEffect> effects;
  const sim::Scenario a = test::discovery_scenario(117, 2, base, 1, &effects);
  const sim::HiddenEffect* flex = drawn(effects, "flex", "roll_rate");
  const sim::HiddenEffect* lag = drawn(effects, "lag");
  ASSERT_TRUE(flex && lag) << "run 117 draws no flex and lag";
  const double flex_s = flex->time_constant_s, lag_s = lag->lag_s;
  RoundAtTheEnd end(a, base_lambda(), {"scalar:roll_rate|lp(2.72)", "second_order"});
  const sim::Simulation& fb = end.fb;
  const Model& model = end.model;
  const Model& start = end.start;
  LoopResult& r = end.r;
  const loop_steps::LoopContext& context = end.context;
  const std::vector<const FlightData*>& flights = end.flights;
  const std::vector<loop_steps::HeldOut>& held = end.held;
  // The time constant alone, estimated again: not enough.
  loop_steps::Round alone(context, 3, &r);
  EXPECT_FALSE(alone.refine_parameters({}));
  {
    // A term without parameters (current:X is field:X written as the wire it models) has none
    // to estimate: beside the lag it is no way in for the lag.
    LoopResult plain;
    plain.model = start;
    plain.model.add_term(TermSpec("current:cur_com_1"));
    fit_model(plain.model, flights);
    plain.rounds.push_back(loop_steps::score(plain.model, flights, "mag_1_c", held, nullptr));
    Diagnosis lag;
    lag.candidates.resize(1);
    lag.candidates[0].term = TermSpec("lag:0.284");
    loop_steps::Round round(context, 3, &plain);
    EXPECT_FALSE(round.refine_parameters({lag}));
  }
  // Beside the lag the round refused (and a candidate of the same channel, tried too).
  Diagnosis dx;
  dx.candidates.resize(2);
  dx.candidates[0].term = TermSpec("lag:0.284");
  dx.candidates[1].term = TermSpec("field:roll_rate|d");
  loop_steps::Round round(context, 3, &r);
  ASSERT_TRUE(round.refine_parameters({dx}));
  ASSERT_EQ(r.rounds.size(), 2u);
  const LoopRound& lr = r.rounds.back();
  ASSERT_EQ(lr.replaced.size(), 1u);
  EXPECT_EQ(lr.replaced[0].first, "scalar:roll_rate|lp(2.72)");
  EXPECT_EQ(lr.added.rfind("lag:0.284 + scalar:roll_rate|lp(", 0), 0u) << lr.added;
  double tau_s = NAN;
  for (const TermSpec& t : r.model.terms)
    if (const ExprTerm* e = t.expr(); e && t.text().rfind("scalar:roll_rate|lp(", 0) == 0)
      tau_s = e->parameters().at(0).second;
  const double before_nT = r.rounds[0].heldout_std_nT, after_nT = lr.heldout_std_nT;
  const double next_before_nT = evaluate_model(model, fb.flight, "mag_1_c", false).std_nT;
  const double next_after_nT = evaluate_model(r.model, fb.flight, "mag_1_c", false).std_nT;
  std::printf(
      "  flex through %.3f s, lag %.3f s: %s; held out %.4f -> %.4f nT, next flight %.3f -> "
      "%.3f nT\n",
      flex_s, lag_s, lr.added.c_str(), before_nT, after_nT, next_before_nT, next_after_nT);
  EXPECT_NEAR(tau_s, flex_s, 0.1 * flex_s);
  EXPECT_LT(after_nT, 0.75 * before_nT);
  EXPECT_LT(next_after_nT, 0.6 * next_before_nT);
  EXPECT_LE(lr.selection_std_nT, r.rounds[0].selection_std_nT);
  EXPECT_LE(lr.confirmation_std_nT, r.rounds[0].confirmation_std_nT);
}

TEST(DiscoveryLong, ARidgeChosenEveryRoundLeavesNoTermStandingInForIt) {
  expect_ridge_leaves_no_stand_in(true);
}

TEST(Discovery, EachEffectIsWrittenExactlyByItsExpectedTerm) {
  // The floor the benchmark compares with (TL + the effects' own terms) rests on
  // sim::expected_term: each effect the simulator adds to mag_5_uc must be a combination of that
  // term's columns, built from the recorded channels and flux_c, plus a constant, to < 2 % of its
  // std (the rest: the fluxgate's noise and its direction against the sensor's).
  sim::Scenario s = sim::load_scenario(test::source_dir() + "/config/scenarios/random_base.yaml");
  // type, channel, gain, time constant (s), threshold (play half-width, relay level).
  const auto effect = [](const std::string& type, const std::string& channel, double gain = 1.0,
                         double time_constant_s = 300.0, double threshold = 0.0) {
    sim::HiddenEffect e;
    e.type = type;
    e.channel = channel;
    e.sensors = {"mag_5_uc"};
    e.direction = Eigen::Vector3d(0.6, -0.48, 0.64);
    e.gain = gain;
    e.time_constant_s = time_constant_s;
    e.threshold = threshold;
    return e;
  };
  std::vector<sim::HiddenEffect> all = {
      effect("wire", "cur_flap"),
      effect("inductive", "cur_strb", 0.05),
      effect("thermal", "cur_tank", 1.0, 150.0),  // |I|^1 (below): the noise about 0 A folded
      effect("thermal", "cur_outpwr", 0.02, 60.0),
      effect("flex", "roll_rate", 1.0, 2.3),
      effect("hysteresis", "cur_acpwr", 1.0, 300.0, 0.5),
      effect("product", "cur_acpwr", 0.05),
      effect("relay", "cur_flap", 20.0, 300.0, 4.0),
      effect("drift", "vol_acpwr", 1.0, 200.0)};
  all[0].position_m = {-3.0, 0.5, 0.2};
  all[2].exponent = 1.0;
  all[6].channel2 = "roll_rate";
  s.hidden = all;
  const sim::Simulation sim = sim::simulate(s, Igrf::installed());
  const TermInputs in = make_term_inputs(sim.flight, "flux_c", 50000.0);
  for (size_t k = 0; k < all.size(); ++k) {
    const std::string term = sim::expected_term(all[k]);
    const Eigen::VectorXd y =
        sim.truth.column("mag_5_uc.hidden." + std::to_string(k) + "." + all[k].type);
    const auto t = make_term(term);
    Eigen::MatrixXd x(sim.flight.size(), t->columns() + 1);
    t->build(in, x.leftCols(t->columns()));
    x.col(t->columns()).setOnes();
    const Eigen::VectorXd c = x.colPivHouseholderQr().solve(y);
    const double sd = std::sqrt((y.array() - y.mean()).square().mean());
    const double left = std::sqrt((y - x * c).array().square().mean());
    std::printf("  %-34s effect %.3f nT, left %.4f nT\n", term.c_str(), sd, left);
    EXPECT_GT(sd, 0.05) << term;
    EXPECT_LT(left, 0.02 * sd) << term;
  }
  EXPECT_EQ(sim::expected_term(effect("ripple", "cur_tank")), "");
  EXPECT_EQ(sim::expected_term(effect("saturation", "cur_tank")), "");
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

TEST(Discovery, AnEffectThePilotFlightCannotSizeIsDrawnAgain) {
  // Run 200 (its states recorded): drawn first, a product of cur_com_1 with the flap angle, on a
  // pilot flight that never extends the flaps (flap_deg its 0.05 deg noise). Sized to 0.47 nT
  // there, it was 201 nT rms on the aircraft's next flight, where the flaps are out 98 % of the
  // time. Another flight of the aircraft now checks each size: the effects drawn show on the next
  // flight within the ratio the check allows.
  sim::Scenario base = base_with_states();
  base.aircraft_seed = 5000 + 200;
  base.seed = 1000 + 2 * 200;
  const auto effects = sim::random_effects(base, 200, 1, Igrf::installed());
  ASSERT_EQ(effects.size(), 1u);
  EXPECT_NE(sim::describe(effects[0]), "product cur_com_1*flap_deg");
  double rms_nT[2];
  for (unsigned next = 0; next < 2; ++next) {
    sim::Scenario s = base;
    s.seed += next;
    s.hidden = effects;
    const sim::Simulation f = sim::simulate(s, Igrf::installed());
    const Eigen::VectorXd c = f.truth.column("mag_5_uc.hidden.0." + effects[0].type);
    rms_nT[next] = std::sqrt((c.array() - c.mean()).square().mean());
    std::printf("  %s: %.3f nT on the %s flight\n", sim::describe(effects[0]).c_str(), rms_nT[next],
                next ? "next" : "pilot");
  }
  EXPECT_GT(rms_nT[0], 0.25);
  EXPECT_LT(rms_nT[0], 3.5);
  EXPECT_LT(rms_nT[1], 50 * rms_nT[0]);
}

TEST(Discovery, ASlowCandidateTheCalibrationRowsCannotSizeIsTriedSizedOnTheLines) {
  // Run 111, second aircraft, its states recorded: heaters of cur_strb (I², 60.5 s) and of
  // cur_srvo_o (I², 48.6 s), and a pick-up of cur_heat. With the strobes' heater and the pick-up
  // written, the diagnosis ranks the servo heater first on both halves of the held-out lines (its
  // screen sizes a slow candidate on the lines); sized on the calibration rows, where the servo
  // current barely heats, the same term raises the held-out error, and the diagnosis with slow
  // terms sized on the lines does not list it (scripts/bench_discovery 1 111 half-several states
  // draws=3 why). The round with slow terms sized on the lines tries it there.
  const sim::Scenario base = base_with_states();
  std::vector<sim::HiddenEffect> effects;
  const sim::Scenario a = test::discovery_scenario(111, 3, base, 1, &effects);
  ASSERT_TRUE(drawn(effects, "thermal", "cur_srvo_o")) << "run 111 draws no heater of cur_srvo_o";
  RoundAtTheEnd end(a, base_lambda(), {"dcurrent:cur_heat"});
  const LoopResult written = end.with_slow_term("field:cur_strb|lp(64.9)");
  const Model& start = written.model;
  const LoopRound& before = written.rounds.back();
  // The servo heater sized on the calibration rows: the held-out error rises.
  Model on_rows = start;
  loop_steps::add_candidate_term(TermSpec("field:cur_srvo_o|pow(2)|lp(48.6)"), true, end.truth,
                                 &on_rows);
  fit_model(on_rows, end.flights);
  const double on_rows_nT =
      loop_steps::score(on_rows, end.flights, end.truth, end.held, nullptr).heldout_std_nT;
  EXPECT_GT(on_rows_nT, before.heldout_std_nT);
  // One round of the loop from there.
  const LoopResult r = diagnose_loop(start, end.flights, end.truth, 1, 0.05, DiagnoseOptions{});
  ASSERT_GE(r.rounds.size(), 2u) << r.stop_reason;
  const LoopRound& kept = r.rounds.back();
  const double next_before_nT = evaluate_model(start, end.fb.flight, "mag_1_c", false).std_nT;
  const double next_now_nT = evaluate_model(r.model, end.fb.flight, "mag_1_c", false).std_nT;
  std::printf(
      "  %s (slow terms sized on the lines: %d): held out %.4f -> %.4f nT (sized on the "
      "calibration rows %.4f), next flight %.3f -> %.3f nT\n",
      kept.added.c_str(), kept.slow_on_lines, r.rounds.front().heldout_std_nT, kept.heldout_std_nT,
      on_rows_nT, next_before_nT, next_now_nT);
  EXPECT_TRUE(kept.slow_on_lines);
  EXPECT_EQ(loop_steps::fields_of(TermSpec(kept.added)), std::set<std::string>{"cur_srvo_o"});
  EXPECT_LT(std::pow(kept.heldout_std_nT / r.rounds.front().heldout_std_nT, 2), 0.8);
  EXPECT_LT(next_now_nT, 0.85 * next_before_nT);
}

TEST(DiscoveryLong, ADriftThatDominatesTheFlightIsSizedOnTheLinesBeforeSmallerTerms) {
  // Run 229, second aircraft, its states recorded: an 848 s drift of cur_tank and a hysteresis
  // of cur_outpwr (play 0.746). Sized on the lines, the drift alone explains four fifths of the
  // held-out error; the calibration rows, where it barely moves, rank a product of the outside
  // air temperature with the pitot heater's switch first (16 %). With the lines tried only once
  // the calibration rows keep nothing, the loop takes that product, then a stand-in of a current
  // that moves with the hysteresis's (cur_acpwr, r 0.99996), and the drift third: the final model
  // names cur_acpwr for the hysteresis (scripts/bench_discovery 1 229 half-several states
  // draws=3 why slow-lines-last). Tried first, the drift is the first round, and the hysteresis
  // is then named by its own channel.
  std::vector<sim::HiddenEffect> effects;
  const sim::Scenario a = test::discovery_scenario(229, 2, base_with_states(), 1, &effects);
  ASSERT_TRUE(drawn(effects, "drift", "cur_tank")) << "run 229 draws no drift of cur_tank";
  RoundAtTheEnd end(a, base_lambda(), {});
  // What the calibration rows rank first.
  const std::vector<loop_steps::Eligible> on_rows = end.round_candidates();
  ASSERT_FALSE(on_rows.empty());
  EXPECT_EQ(loop_steps::fields_of(on_rows.front().term).count("cur_tank"), 0u);
  EXPECT_LT(on_rows.front().explained, kSlowLinesFirstShare / kSlowLinesFirstRatio);
  // One round of the loop, without the steps of its end (each is the subject of its own tests).
  DiagnoseOptions options;
  options.refine_parameters = false;
  options.exchange_terms = false;
  options.chance_control = false;
  options.better_look_alike = false;
  options.drop_idle_factors = false;
  options.steady_factor_products = false;
  options.redundant_once_refined = false;
  const LoopResult r = diagnose_loop(end.start, end.flights, end.truth, 1, 0.05, options);
  ASSERT_GE(r.rounds.size(), 2u) << r.stop_reason;
  const LoopRound& kept = r.rounds[1];
  std::printf(
      "  start %.4f nT held out; the calibration rows rank %s first (%.1f %%); round 1: "
      "%s, %.4f nT (on the lines: %d)\n",
      r.rounds[0].heldout_std_nT, on_rows.front().term.text().c_str(),
      100 * on_rows.front().explained, kept.added.c_str(), kept.heldout_std_nT, kept.slow_on_lines);
  EXPECT_TRUE(kept.slow_on_lines);
  EXPECT_EQ(loop_steps::fields_of(TermSpec(kept.added)), std::set<std::string>{"cur_tank"});
  EXPECT_LT(kept.heldout_std_nT, 0.25 * r.rounds[0].heldout_std_nT);
}

TEST(Discovery, ALoadsFieldWhoseSizeFollowsAStateIsWrittenAsThePair) {
  // Run 105, first aircraft, its states recorded: a wire of cur_heat and a product
  // cur_heat*oat_degC, one field whose size follows the outside air temperature. The
  // calibration boxes are flown at 3000 m (-4.5 degC), the survey lines at 487 m (12 degC): the
  // band-pass sizes the heater's field at the boxes' temperature, and neither term alone holds
  // on the lines, so no single term passes (without this step the loop ends at TL, 0.515 nT on
  // the next flight; scripts/bench_discovery 1 105 half-several states draws=3 why). The screen
  // ranks the pair of cur_heat with oat_degC first, and the pair, sized as slow terms on the
  // calibration rows and the lines, is kept.
  const sim::Scenario base = base_with_states();
  std::vector<sim::HiddenEffect> effects;
  const sim::Scenario a = test::discovery_scenario(105, 2, base, 0, &effects);
  ASSERT_TRUE(drawn(effects, "wire", "cur_heat")) << "run 105 draws no wire of cur_heat";
  ASSERT_TRUE(drawn(effects, "product", "cur_heat")) << "run 105 draws no product of cur_heat";
  RoundAtTheEnd end(a, base_lambda(), {});
  const double before_nT = end.r.rounds.back().heldout_std_nT;
  const double next_tl_nT = evaluate_model(end.start, end.fb.flight, "mag_1_c", false).std_nT;
  // As the loop's round that sizes slow terms on the lines too: every line beside the
  // calibration's (the model has no slow term yet, so its scores do not change).
  {
    std::set<double> lines;
    const auto line = end.fa.flight.column("line");
    const FitSettings& fit = end.r.model.fit;
    for (Eigen::Index i = 0; i < line.size(); ++i)
      if (std::find(fit.lines.begin(), fit.lines.end(), line[i]) == fit.lines.end())
        lines.insert(line[i]);
    end.r.model.fit.slow_lines.assign(lines.begin(), lines.end());
  }
  loop_steps::Round round(end.context, 1, &end.r);
  ASSERT_TRUE(round.size_following_a_state());
  const LoopRound& kept = end.r.rounds.back();
  EXPECT_EQ(kept.added, "current:cur_heat + field:cur_heat*oat_degC");
  EXPECT_TRUE(kept.together);
  ASSERT_EQ(kept.alone_std_nT.size(), 2u);
  const double next_nT = evaluate_model(end.r.model, end.fb.flight, "mag_1_c", false).std_nT;
  std::printf("  %s: held out %.4f -> %.4f nT (alone %.4f, %.4f), next flight %.3f -> %.3f nT\n",
              kept.added.c_str(), before_nT, kept.heldout_std_nT, kept.alone_std_nT[0],
              kept.alone_std_nT[1], next_tl_nT, next_nT);
  // Neither term alone lowers the held-out error by the accepted share; the pair, by far more.
  for (double alone_nT : kept.alone_std_nT)
    EXPECT_GT(alone_nT * alone_nT, 0.95 * before_nT * before_nT);
  EXPECT_LT(kept.heldout_std_nT, 0.6 * before_nT);
  EXPECT_LT(next_nT, 0.4 * next_tl_nT);
  // With the pair written, no other pair of a load and a state passes.
  loop_steps::Round again(end.context, 2, &end.r);
  EXPECT_FALSE(again.size_following_a_state()) << end.r.rounds.back().added;
}

// The rows of `loop` that share its last round's number after that round's first: the changes
// made once the rounds are spent.
std::vector<const LoopRound*> rows_after_the_rounds(const LoopResult& loop, int rounds) {
  std::vector<const LoopRound*> rows;
  size_t first = 0;
  while (first < loop.rounds.size() && loop.rounds[first].round != rounds) ++first;
  for (size_t k = first + 1; k < loop.rounds.size(); ++k) rows.push_back(&loop.rounds[k]);
  return rows;
}

// Run r's first and next flights on aircraft draw d (states recorded, `count` effects drawn,
// in `effects`), and the loop of kLoopRounds rounds from TL fitted on the first flight.
constexpr int kLoopRounds = 5;
struct WholeLoop {
  sim::Simulation first, next;
  LoopResult loop;
};
WholeLoop whole_loop(unsigned r, int count, unsigned d, std::vector<sim::HiddenEffect>* effects) {
  const sim::Scenario a = test::discovery_scenario(r, count, base_with_states(), d, effects);
  WholeLoop w{sim::simulate(a, Igrf::installed()),
              sim::simulate(RoundAtTheEnd::next_of(a), Igrf::installed()),
              {}};
  Model start = load_model_yaml(test::source_dir() + "/config/models/tl_sim.yaml");
  fit_model(start, {&w.first.flight});
  // TL as given (DiagnoseOptions::exact_norm off): these cases test the corrections made once
  // the rounds are spent, on the path the loop takes with TL's first-order expansion; with TL
  // written as the exact norm, run 117 reaches its end by another path.
  DiagnoseOptions tl_as_given;
  tl_as_given.exact_norm = false;
  w.loop = diagnose_loop(start, w.first.flight, "mag_1_c", kLoopRounds, 0.05, tl_as_given);
  return w;
}

TEST(DiscoveryLong, TheKeptTermsParametersAreEstimatedAgainOnceTheRoundsAreSpent) {
  // Run 107, second aircraft: drifts of vol_fan (120 s) and vol_acpwr (141 s) and an inductive
  // pick-up of cur_tank. The loop's five rounds add a stand-in of vol_block, the pick-up, the fan's
  // drift through 74.1 s (sized while the bus drift was still in the residual) and a stand-in of
  // cur_acpwr, and the fifth estimates the first's time constant again. The rounds limit what is
  // added, not what is corrected: once they are spent, the kept terms' parameters are estimated
  // again with every other term in place (the fan's drift through 100 s, the bus stand-in's
  // through 119 s), each a round sharing the last round's number.
  std::vector<sim::HiddenEffect> effects;
  const WholeLoop w = whole_loop(107, 3, 1, &effects);
  const sim::HiddenEffect* fan = drawn(effects, "drift", "vol_fan");
  ASSERT_TRUE(fan) << "run 107 draws no drift of vol_fan";
  const sim::Simulation &fa = w.first, &fb = w.next;
  const LoopResult& loop = w.loop;
  // The rows after the last round's first: the corrections made once the rounds are spent.
  const std::vector<const LoopRound*> rows = rows_after_the_rounds(loop, kLoopRounds);
  ASSERT_FALSE(rows.empty()) << "no correction after the last round";
  Model undone = loop.model;
  std::string fan_term;
  for (const LoopRound* row : rows) {
    const LoopRound& lr = *row;
    EXPECT_EQ(lr.round, kLoopRounds);
    const std::vector<std::string> to = loop_steps::step_terms(lr.added);
    ASSERT_EQ(to.size(), lr.replaced.size()) << lr.added;
    for (size_t i = 0; i < to.size(); ++i) {
      const auto& [from, why] = lr.replaced[i];
      EXPECT_NE(why.find("its parameters estimated again"), std::string::npos) << why;
      undone = loop_steps::with_term_as(undone, to[i], from);
      if (from.find("vol_fan|lp(") != std::string::npos) fan_term = from;
    }
  }
  double tau_before_s = NAN, tau_after_s = NAN;
  for (const TermSpec& t : loop.model.terms)
    if (const ExprTerm* e = t.expr(); e && t.text().find("vol_fan|lp(") != std::string::npos)
      tau_after_s = e->parameters().at(0).second;
  if (const auto e = parse_expr_term(fan_term)) tau_before_s = e->parameters().at(0).second;
  fit_model(undone, {&fa.flight});
  const double next_before_nT = evaluate_model(undone, fb.flight, "mag_1_c", false).std_nT;
  const double next_after_nT = evaluate_model(loop.model, fb.flight, "mag_1_c", false).std_nT;
  std::printf("  fan's drift through %.0f s: %.1f s -> %.1f s; next flight %.3f -> %.3f nT\n",
              fan->time_constant_s, tau_before_s, tau_after_s, next_before_nT, next_after_nT);
  EXPECT_LT(std::abs(tau_after_s - fan->time_constant_s),
            0.5 * std::abs(tau_before_s - fan->time_constant_s));
  EXPECT_LT(next_after_nT, 0.9 * next_before_nT);
}

TEST(DiscoveryLong, TheModelsLagIsEstimatedAgainOnceTheRoundsAreSpent) {
  // Run 117, second aircraft: a 0.271 s lag of the scalar and a flex of the roll rate through
  // 0.825 s. The lag is written in round 1 (0.349 s) beside the flex still in the residual;
  // stand-ins of the flex fill rounds 2 to 5. Once the rounds are spent, the model without one
  // of them (field:ins_vn), diagnosed again, ranks the lag again at 0.272 s: held out 0.6831 ->
  // 0.4652 nT, next flight 1.778 -> 0.331 nT. A lag found before the other effects were written
  // is a correction, not an added term: a model has one lag, so the new value takes the old
  // one's place, and the rounds say so (record_displaced_lags).
  std::vector<sim::HiddenEffect> effects;
  const WholeLoop w = whole_loop(117, 2, 1, &effects);
  const sim::HiddenEffect* lag = drawn(effects, "lag");
  ASSERT_TRUE(lag) << "run 117 draws no lag";
  const sim::Simulation &fa = w.first, &fb = w.next;
  const LoopResult& loop = w.loop;
  std::string old_lag, new_lag;
  double before_nT = NAN, after_nT = NAN;
  const std::vector<const LoopRound*> rows = rows_after_the_rounds(loop, kLoopRounds);
  for (size_t k = 0; k < rows.size(); ++k)
    for (const auto& [from, why] : rows[k]->replaced)
      if (from.rfind("lag:", 0) == 0) {
        EXPECT_NE(why.find("its value estimated again"), std::string::npos) << why;
        old_lag = from;
        new_lag = rows[k]->added;
        after_nT = rows[k]->heldout_std_nT;
        before_nT = k ? rows[k - 1]->heldout_std_nT
                      : loop.rounds[loop.rounds.size() - rows.size() - 1].heldout_std_nT;
      }
  ASSERT_FALSE(old_lag.empty()) << "no lag estimated again after the last round";
  const double old_s = std::stod(old_lag.substr(4)), new_s = loop.model.scalar_lag_s();
  EXPECT_EQ(new_lag.rfind("lag:", 0), 0u) << new_lag;
  Model undone = loop_steps::with_term_as(loop.model, new_lag, old_lag);
  fit_model(undone, {&fa.flight});
  const double next_before_nT = evaluate_model(undone, fb.flight, "mag_1_c", false).std_nT;
  const double next_after_nT = evaluate_model(loop.model, fb.flight, "mag_1_c", false).std_nT;
  std::printf(
      "  lag %.3f s: %.3f s -> %.3f s; held out %.4f -> %.4f nT; next flight %.3f -> %.3f "
      "nT\n",
      lag->lag_s, old_s, new_s, before_nT, after_nT, next_before_nT, next_after_nT);
  // As any term must: the accepted share of the held-out variance and the resolution.
  const DiagnoseOptions defaults;
  EXPECT_LE(after_nT, before_nT * std::sqrt(1.0 - defaults.accept_fraction));
  EXPECT_LE(after_nT, before_nT - defaults.resolution_nT);
  EXPECT_LT(std::abs(new_s - lag->lag_s), 0.5 * std::abs(old_s - lag->lag_s));
  EXPECT_LT(next_after_nT, 0.95 * next_before_nT);
}

TEST(DiscoveryLong, ATermAnExchangeMakesRedundantLeaves) {
  // Run 117, first aircraft: a 0.271 s lag and a flex of the roll rate through 0.825 s. Once the
  // rounds are spent, the flex's term is estimated again together with the roll rate's
  // derivative, and two exchanges put the lag in place of a product of the roll rate and the
  // pitch rate's term in place of its derivative. With these in place the derivative of the roll
  // rate no longer earns its place: the backward pass follows every change, not only a round
  // that adds a term, and the term leaves.
  std::vector<sim::HiddenEffect> effects;
  const WholeLoop w = whole_loop(117, 2, 0, &effects);
  const sim::Simulation &fa = w.first, &fb = w.next;
  const LoopResult& loop = w.loop;
  std::string gone;
  const LoopRound* at = nullptr;
  for (const LoopRound* lr : rows_after_the_rounds(loop, kLoopRounds))
    if (!lr->replaced.empty() && !lr->removed.empty()) {
      at = lr;
      gone = lr->removed.front().first;
      EXPECT_NE(lr->removed.front().second.find("made redundant"), std::string::npos);
    }
  ASSERT_TRUE(at) << "no term leaves after a change made once the rounds are spent";
  for (const TermSpec& t : loop.model.terms) EXPECT_NE(t.text(), gone);
  Model with = loop.model;
  with.add_term(TermSpec(gone));
  with.coefficients.resize(0);
  fit_model(with, {&fa.flight});
  const double next_with_nT = evaluate_model(with, fb.flight, "mag_1_c", false).std_nT;
  const double next_without_nT = evaluate_model(loop.model, fb.flight, "mag_1_c", false).std_nT;
  std::printf("  %s leaves after %s: next flight %.3f -> %.3f nT\n", gone.c_str(),
              at->added.c_str(), next_with_nT, next_without_nT);
  EXPECT_NE(gone.find("roll_rate"), std::string::npos) << gone;
  // What it took from the residual the others carry: the next flight is no worse without it.
  EXPECT_LE(next_without_nT, next_with_nT);
}

// The base flight with no hidden effect, aircraft seed 77: flight 5, its next flight 6, and TL
// (tl_sim.yaml) fitted on the first with its error on the next, nT.
struct NoEffectFlights {
  static sim::Scenario flight(unsigned seed) {
    sim::Scenario s = sim::load_scenario(test::source_dir() + "/config/scenarios/random_base.yaml");
    s.aircraft_seed = 77;
    s.seed = seed;
    return s;
  }
  bool hidden_none = flight(5).hidden.empty();
  sim::Simulation first = sim::simulate(flight(5), Igrf::installed());
  sim::Simulation next = sim::simulate(flight(6), Igrf::installed());
  Model tl = fitted_tl();
  double tl_next_nT = evaluate_model(tl, next.flight, "mag_1_c", false).std_nT;
  Model fitted_tl() const {
    Model m = load_model_yaml(test::source_dir() + "/config/models/tl_sim.yaml");
    fit_model(m, {&first.flight});
    return m;
  }
};

TEST(Discovery, TheSecondOrderTermIsSizedOnTheLinesWhereNoEffectIsHidden) {
  // The base flight with no hidden effect (aircraft seed 77, flights 5 and 6): the scalar is the
  // norm of the Earth's field plus the aircraft's permanent, induced and eddy fields, which TL
  // writes to first order only. Its dropped second-order part (quartic in the field's direction,
  // SecondOrderTerm) is 15 columns beside TL's 18 that the two minutes of calibration segments
  // cannot size: fitted there by the band-pass, the next flight's error rises several times.
  // Sized on the held-out lines (cross-fitted, as a slow candidate is), it explains most of the
  // residual TL leaves, and the loop writes it rather than a channel that stands in for it: the
  // model names no channel where no effect is hidden.
  const NoEffectFlights w;
  ASSERT_TRUE(w.hidden_none);
  const sim::Simulation &fa = w.first, &fb = w.next;
  const Model& start = w.tl;
  const double tl_next_nT = w.tl_next_nT;
  // The second-order term sized by the band-pass on the calibration segments.
  Model on_rows = start;
  on_rows.add_term(TermSpec("second_order"));
  on_rows.coefficients.resize(0);
  fit_model(on_rows, {&fa.flight});
  const double on_rows_next_nT = evaluate_model(on_rows, fb.flight, "mag_1_c", false).std_nT;
  // TL as given (DiagnoseOptions::exact_norm off): the loop's own sizing of what TL drops
  // (Discovery.TlIsWrittenAsTheExactNormWhereNoEffectIsHidden has it written exactly).
  DiagnoseOptions tl_as_given;
  tl_as_given.exact_norm = false;
  const LoopResult loop = diagnose_loop(start, fa.flight, "mag_1_c", 5, 0.05, tl_as_given);
  const double loop_next_nT = evaluate_model(loop.model, fb.flight, "mag_1_c", false).std_nT;
  std::string added;
  std::set<std::string> channels;
  for (const TermSpec& t : loop.model.terms) {
    if (std::find(start.terms.begin(), start.terms.end(), t) != start.terms.end()) continue;
    added += " " + t.text();
    const std::set<std::string> f = loop_steps::fields_of(t);
    channels.insert(f.begin(), f.end());
  }
  std::printf(
      "  no hidden effect: next flight TL %.3f nT, TL + second_order on the calibration rows "
      "%.3f nT, the loop (%s) %.3f nT\n",
      tl_next_nT, on_rows_next_nT, added.c_str(), loop_next_nT);
  EXPECT_GT(on_rows_next_nT, 2 * tl_next_nT);
  EXPECT_NE(std::find(loop.model.slow_terms.begin(), loop.model.slow_terms.end(),
                      TermSpec("second_order")),
            loop.model.slow_terms.end())
      << added;
  for (const std::string& c : channels)
    EXPECT_FALSE(is_aircraft_state(c) || is_motion_channel(c)) << c << " named in" << added;
  EXPECT_LT(loop_next_nT, 0.75 * tl_next_nT);
}

TEST(Discovery, TlIsWrittenAsTheExactNormWhereNoEffectIsHidden) {
  // The same flights (no hidden effect, aircraft 77, flights 5 and 6). What TL leaves there is
  // its own first-order expansion of the norm: the loop writes TL as the exact norm (`norm`, its
  // column from TL's own coefficients) and, the flights recording the stinger, fits it against
  // the stinger on the same calibration segments. It names no channel, and the next flight falls
  // from TL's 0.176 nT to about the sensors' noise.
  const NoEffectFlights w;
  ASSERT_TRUE(w.hidden_none);
  const sim::Simulation &fa = w.first, &fb = w.next;
  const Model& start = w.tl;
  const double tl_next_nT = w.tl_next_nT;
  const LoopResult loop = diagnose_loop(start, fa.flight, "mag_1_c", 5, 0.05, DiagnoseOptions{});
  const double loop_next_nT = evaluate_model(loop.model, fb.flight, "mag_1_c", false).std_nT;
  std::string added, change;
  std::set<std::string> channels;
  for (const TermSpec& t : loop.model.terms) {
    if (std::find(start.terms.begin(), start.terms.end(), t) != start.terms.end()) continue;
    added += " " + t.text();
    const std::set<std::string> f = loop_steps::fields_of(t);
    channels.insert(f.begin(), f.end());
  }
  for (const LoopRound& lr : loop.rounds)
    if (!lr.model_change.empty()) change = lr.model_change + " (" + lr.added + ")";
  std::printf("  no hidden effect: next flight TL %.3f nT, the loop (%s; %s) %.4f nT\n", tl_next_nT,
              added.c_str(), change.c_str(), loop_next_nT);
  EXPECT_NE(change.find("fit.method reference (mag_1_c)"), std::string::npos) << change;
  EXPECT_NE(std::find(loop.model.terms.begin(), loop.model.terms.end(), TermSpec("norm")),
            loop.model.terms.end());
  EXPECT_EQ(loop.model.fit.method, FitMethod::kReference);
  EXPECT_TRUE(channels.empty()) << added;
  EXPECT_LT(loop_next_nT, 0.03);
  EXPECT_LT(loop_next_nT, 0.2 * tl_next_nT);
}

TEST(Discovery, TheExactNormAndAWireOnTheCalibrationRowsAreKeptTogether) {
  // Run 168, first aircraft, its states recorded: a wire of cur_srvo_m, the servo current that
  // the compensation maneuvers drive hardest. Under the band-pass TL its term does not hold on
  // both halves (0.325 -> 0.344 nT held out), and TL as the exact norm fitted against the
  // reference alone is worse still: the wire's field on the calibration rows pulls TL's
  // coefficients off. Without this step the loop stops there with TL alone, 0.457 nT on the next
  // flight against the oracle's 0.383 (scripts/bench_discovery 1 168 half-several states
  // draws=3 norm-alone). The exact norm, diagnosed, ranks the wire first; the two together leave
  // the held-out lines near their noise.
  std::vector<sim::HiddenEffect> effects;
  const sim::Scenario a = test::discovery_scenario(168, 1, base_with_states(), 0, &effects);
  ASSERT_EQ(effects.size(), 1u);
  ASSERT_EQ(effects.front().type, "wire");
  ASSERT_EQ(effects.front().channel, "cur_srvo_m");
  RoundAtTheEnd end(a, base_lambda(), {});
  const LoopRound before = end.r.rounds.back();
  // Alone, the exact norm is refused.
  EXPECT_FALSE(loop_steps::exact_norm_step(end.model, before, end.flights, end.truth, end.held,
                                           nullptr, end.options));
  DiagnoseOptions round_options;
  round_options.slow_terms_on_lines = false;  // as the loop's rounds diagnose first
  loop_steps::Round round(end.context, 1, &end.r);
  ASSERT_TRUE(round.exact_norm_with_a_term(round_options));
  const LoopRound& kept = end.r.rounds.back();
  const std::vector<std::string> added = loop_steps::step_terms(kept.added);
  std::printf(
      "  run 168/0: %s: held out %.4f -> %.4f nT (halves %.4f -> %.4f, %.4f -> %.4f); alone "
      "%.3f and %.3f nT; %s\n",
      kept.added.c_str(), before.heldout_std_nT, kept.heldout_std_nT, before.selection_std_nT,
      kept.selection_std_nT, before.confirmation_std_nT, kept.confirmation_std_nT,
      kept.alone_std_nT.at(0), kept.alone_std_nT.at(1), kept.model_change.c_str());
  EXPECT_TRUE(kept.together);
  EXPECT_NE(std::find(added.begin(), added.end(), "norm"), added.end()) << kept.added;
  EXPECT_NE(std::find(added.begin(), added.end(), "current:cur_srvo_m"), added.end()) << kept.added;
  EXPECT_EQ(kept.model_change.rfind("TL as the exact norm", 0), 0u) << kept.model_change;
  // Each alone does worse than the model before; together they leave a tenth of its error.
  ASSERT_EQ(kept.alone_std_nT.size(), 2u);
  for (double alone_nT : kept.alone_std_nT) EXPECT_GT(alone_nT, before.heldout_std_nT);
  EXPECT_LT(kept.heldout_std_nT, 0.1 * before.heldout_std_nT);
  EXPECT_LT(kept.selection_std_nT, before.selection_std_nT);
  EXPECT_LT(kept.confirmation_std_nT, before.confirmation_std_nT);
  // It carries to the next flight: below the oracle's band-pass TL with the wire.
  Model oracle = end.start;
  oracle.coefficients.resize(0);
  oracle.add_term(TermSpec("current:cur_srvo_m"));
  fit_model(oracle, end.flights);
  const double tl_next_nT = end.next_nT(end.start), oracle_next_nT = end.next_nT(oracle);
  const double next_nT = end.next_nT(end.r.model);
  std::printf("  next flight: TL %.3f nT, TL with the wire %.3f nT, kept %.3f nT\n", tl_next_nT,
              oracle_next_nT, next_nT);
  EXPECT_LT(next_nT, 0.5 * oracle_next_nT);
  EXPECT_LT(next_nT, 0.1 * tl_next_nT);
}

}  // namespace
}  // namespace magcomp
