// diagnose: every hidden effect is found with its parameters and the loop reaches the error the
// truth gives; nothing is accepted where nothing is hidden; the inexpressible is reported as
// structure that remains; bad input.
#include <gtest/gtest.h>

#include <algorithm>
#include <fstream>
#include <limits>
#include <nlohmann/json.hpp>
#include <random>
#include <set>
#include <stdexcept>

#include "../../src/core/diagnose/search.h"  // verdict_of
#include "magcomp/core/diagnose/diagnose.h"
#include "magcomp/core/diagnose/diagnose_loop.h"
#include "magcomp/core/diagnose/term_support.h"
#include "magcomp/core/error.h"
#include "magcomp/core/fit/model_fit.h"
#include "magcomp/core/fit/parameter_fit.h"
#include "magcomp/core/io/flight_data.h"
#include "magcomp/core/model/terms_expr.h"
#include "scenario_cache.h"

namespace magcomp {
namespace {

double floor_std() { return test::tl_std(test::scenario("tl_only").flight); }

// Pooled std of a fitted model's error over the given lines, nT.
double std_on(const Model& m, const FlightData& f, const std::vector<double>& lines) {
  const Evaluation ev = evaluate_model(m, f, "mag_1_c");
  double ss = 0, n = 0;
  for (const auto& l : ev.per_line) {
    if (std::find(lines.begin(), lines.end(), l.line) == lines.end()) continue;
    ss += l.std_nT * l.std_nT * static_cast<double>(l.n);
    n += static_cast<double>(l.n);
  }
  return std::sqrt(ss / n);
}

// The loop's rounds that added terms of effects (round 0 first; a round that only chose the
// ridge strength, LoopRound::regularisation, or wrote TL as the exact norm,
// LoopRound::model_change, left out).
std::vector<LoopRound> term_rounds(const LoopResult& r) {
  std::vector<LoopRound> out;
  for (const LoopRound& lr : r.rounds)
    if (!lr.regularisation && lr.model_change.empty()) out.push_back(lr);
  return out;
}

// The rounds of term_rounds that add an effect: not those adding only TL's own form (its
// second-order term, the exact norm, a bias), which reads no channel.
std::vector<LoopRound> effect_rounds(const LoopResult& r) {
  std::vector<LoopRound> out;
  for (const LoopRound& lr : term_rounds(r)) {
    std::string rest = lr.added;
    for (const char* own : {"second_order", "norm", "bias", " + "}) {
      for (size_t at; (at = rest.find(own)) != std::string::npos;)
        rest.erase(at, std::string(own).size());
    }
    if (lr.round == 0 || !rest.empty()) out.push_back(lr);
  }
  return out;
}

// The lines of a flight that the starting model's fit never saw.
std::vector<double> unfitted_lines(const Model& start, const Model& final_model,
                                   const FlightData& f) {
  std::vector<double> held;
  for (const auto& l : evaluate_model(final_model, f, "mag_1_c").per_line) {
    if (std::find(start.fit.lines.begin(), start.fit.lines.end(), l.line) == start.fit.lines.end())
      held.push_back(l.line);
  }
  return held;
}

// The error the truth gives: the hidden effects subtracted from the scalar (truth file), then the
// same TL fit, on the same held-out lines.
double truth_std(const sim::Simulation& s, const Model& start, const std::vector<double>& lines) {
  FlightData clean = s.flight;
  Eigen::VectorXd& scalar = clean.mutable_column("mag_5_uc");
  for (const auto& name : s.truth.names()) {
    if (name.rfind("mag_5_uc.hidden.", 0) == 0) scalar -= s.truth.column(name);
  }
  Model m = start;
  fit_model(m, {&clean});
  return std_on(m, clean, lines);
}

double parameter(const std::string& term, TransformKind kind) {
  const auto e = parse_expr_term(term);
  if (!e) return NAN;
  for (const auto& t : e->signal().transforms)
    if (t.kind == kind) return t.param;
  return NAN;
}

// Each shipped scenario's hidden effect is the top candidate of one diagnosis, accepted, and adding
// it removes the excess; the grammar's grown chains are well formed, and the best candidate of
// another channel explains far less.
void expect_ranked_first(const std::vector<std::pair<std::string, std::string>>& cases) {
  const double floor = floor_std();
  for (const auto& [name, expected] : cases) {
    const FlightData& f = test::scenario(name).flight;
    const Model tl = test::calibrated_tl(f);
    const Diagnosis dx = diagnose(tl, f, "mag_1_c");
    ASSERT_FALSE(dx.candidates.empty());
    const Candidate& top = dx.candidates.front();
    if (expected.rfind("lag:", 0) == 0) {  // the lag to 0.02 s
      ASSERT_EQ(top.term.text().rfind("lag:", 0), 0u) << top.term;
      EXPECT_NEAR(std::stod(top.term.text().substr(4)), std::stod(expected.substr(4)), 0.02);
    } else {
      EXPECT_EQ(top.term, expected) << name;
    }
    EXPECT_TRUE(top.accepted) << name;
    const double before = evaluate_model(tl, f, "mag_1_c").std_nT;
    const double after = test::tl_std(f, {top.term});
    std::printf(
        "  %-18s top %-18s explains %5.1f%% (selection %5.1f%%, confirmation %5.1f%%): "
        "std %.3f -> %.3f nT (floor %.3f); %ld terms fitted\n",
        name.c_str(), top.term.text().c_str(), 100 * top.explained_fraction,
        100 * top.explained_selection, 100 * top.explained_confirmation, before, after, floor,
        dx.candidates_tried);
    EXPECT_TRUE(after * 5.0 <= before || after <= 1.5 * floor) << name;
    // The best candidate of another channel explains far less: the ranking is not a coin toss.
    // (For the lag, the other timing errors are its near-equivalents: a first-order response
    // of the scalar, or a response to the field's rate.)
    // The grammar search: each grown chain is a scored candidate plus one transform at its
    // front or back, within the budget of three, and none rests on a time constant at the top
    // of its scan.
    int grown = 0;
    const double slowest =
        parameter_grid(TransformKind::LowPass, f.dt_s(), f.tt()[f.size() - 1] - f.tt()[0]).back();
    std::set<std::string> terms;
    for (const auto& c : dx.candidates) terms.insert(c.term);
    for (const auto& c : dx.candidates) {
      if (c.family != "chain (grammar search)") continue;
      ++grown;
      const auto e = parse_expr_term(c.term);
      ASSERT_TRUE(e) << c.term;
      const SignalExpr& sig = e->signal();
      ASSERT_GE(sig.transforms.size(), 1u) << c.term;
      EXPECT_LE(sig.transforms.size(), 3u) << c.term;
      SignalExpr front = sig, back = sig;
      front.transforms.erase(front.transforms.begin());
      back.transforms.pop_back();
      auto spec_of = [&](const SignalExpr& x) {
        if (x.transforms.empty() && x.sources.size() == 1) {  // a plain channel's shorthand
          const std::string plain = ExprTerm(e->projection(), x).spec();
          for (const std::string p : {"current:", "rate:"}) {
            if (terms.count(p + x.sources[0])) return p + x.sources[0];
          }
          return plain;
        }
        if (x.transforms.size() == 1 && x.transforms[0].kind == TransformKind::Derivative &&
            x.sources.size() == 1 && terms.count("dcurrent:" + x.sources[0])) {
          return "dcurrent:" + x.sources[0];
        }
        return ExprTerm(e->projection(), x).spec();
      };
      EXPECT_TRUE(terms.count(spec_of(front)) || terms.count(spec_of(back)))
          << c.term << " grows no scored term";
      for (const auto& t : sig.transforms) {
        if (t.kind == TransformKind::LowPass) {
          EXPECT_LT(t.param, 0.99 * slowest) << c.term;
        }
      }
    }
    EXPECT_GT(grown, 0) << name;
    const bool timing = top.family == "scalar lag";
    for (const auto& c : dx.candidates) {
      if (c.family == "scalar lag") continue;
      if (timing && (c.family == "scalar sensor response" || c.channel.empty())) continue;
      if (!top.channel.empty() && c.channel.find(top.channel) != std::string::npos) continue;
      EXPECT_LT(c.explained_fraction, 0.5 * top.explained_fraction)
          << name << " " << c.term << " (" << c.family << ")";
      break;
    }
  }
}

TEST(Diagnose, EveryShippedHiddenEffectIsRankedFirstAndAddingItRemovesTheExcess) {
  // The fuel pump's wire, a wire like the strobe's: DiagnoseLong.
  expect_ranked_first({{"wire_strobe", "current:cur_strb"},
                       {"inductive_heater", "dcurrent:cur_heat"},
                       {"lag", "lag:0.3"}});
}

TEST(DiagnoseLong, TheFuelPumpsWireIsRankedFirstAndAddingItRemovesTheExcess) {
  expect_ranked_first({{"fuel_pump_wire", "current:cur_tank"}});
}

TEST(DiagnoseLong, TwoHiddenEffectsAreFoundInTwoRoundsAndReachTheFloor) {
  const FlightData& f = test::scenario("two_effects").flight;
  const LoopResult r = diagnose_loop(test::calibrated_tl(f), f, "mag_1_c", 5, 0.05, {});
  std::set<std::string> added;
  for (const auto& lr : r.rounds) {
    std::printf("  round %d: %-22s held-out %.3f nT\n", lr.round, lr.added.c_str(),
                lr.heldout_std_nT);
    if (lr.round > 0 && !lr.regularisation && lr.model_change.empty())
      added.insert(lr.added.substr(0, lr.added.find(':')));
    // The strobe's current is told apart from every other channel: no look-alike.
    for (const auto& [term, std_nT] : lr.look_alikes)
      ADD_FAILURE() << lr.added << " has the look-alike " << term << " (" << std_nT << " nT)";
  }
  ASSERT_EQ(term_rounds(r).size(), 3u) << r.stop_reason;
  EXPECT_EQ(added, (std::set<std::string>{"lag", "current"}));
  EXPECT_LT(r.rounds.back().all_std_nT, 1.5 * floor_std());
}

// The user's loop on the scenarios whose hidden effect no fixed menu of terms says: TL
// against the reference on the training lines, then diagnose and add the top term while it is
// accepted and explains 5 %, at most 5 rounds. It must reach the error the truth gives on the
// lines the start never fitted, in the given number of term rounds, with each transform's
// parameter and the lag within 20 % of the truth.
struct NewEffectCase {
  std::string scenario;
  std::vector<std::pair<TransformKind, double>> parameters;  // kind, truth
  double lag_s;                                              // truth, NaN: none
  size_t rounds;                                             // terms the loop should add
};

void expect_loop_reaches_truth(const std::vector<NewEffectCase>& cases) {
  for (const NewEffectCase& c : cases) {
    const sim::Simulation& s = test::scenario(c.scenario);
    const Model start = test::reference_tl(s.flight);
    const LoopResult r = diagnose_loop(start, s.flight, "mag_1_c", 5, 0.05, {});
    const std::vector<double> held = unfitted_lines(start, r.model, s.flight);
    Model tl = start;
    fit_model(tl, {&s.flight});
    const double truth = truth_std(s, start, held);
    const double tl_err = std_on(tl, s.flight, held);
    const double final_err = std_on(r.model, s.flight, held);
    std::printf("  %-17s TL %.3f nT -> %.3f nT in %zu rounds (the truth gives %.3f; limit %.3f):",
                c.scenario.c_str(), tl_err, final_err, r.rounds.size() - 1, truth,
                1.5 * truth + 0.05);
    for (const auto& lr : r.rounds) {
      if (lr.round > 0) std::printf(" %s (%.3f)", lr.added.c_str(), lr.heldout_std_nT);
    }
    std::printf("\n");
    EXPECT_LE(final_err, 1.5 * truth + 0.05) << c.scenario;
    EXPECT_LT(final_err, tl_err) << c.scenario;
    // The effect's term (TL's own second-order term may follow it, sized on the lines).
    EXPECT_EQ(effect_rounds(r).size() - 1, c.rounds) << c.scenario << ": " << r.stop_reason;
    for (const auto& [kind, value] : c.parameters) {
      double found = NAN;
      for (const auto& t : r.model.terms) {
        if (std::isnan(found)) found = parameter(t, kind);
      }
      EXPECT_NEAR(found, value, 0.2 * value) << c.scenario;
    }
    if (!std::isnan(c.lag_s)) {
      EXPECT_NEAR(r.model.scalar_lag_s(), c.lag_s, 0.2 * c.lag_s);
    }
  }
}

TEST(Diagnose, TheLoopReachesTheTruthErrorWithTheRightParametersOnEveryNewEffect) {
  // A heater; the eddy currents' decay, the wing's flex (flex_load) and a lag, a wire and a
  // heater together: DiagnoseLong.
  expect_loop_reaches_truth({{"thermal_heater", {{TransformKind::LowPass, 150.0}}, NAN, 1}});
}

// The long tests (suites *Long) run in scripts/bench_long_tests, not in the test command.
TEST(DiagnoseLong, TheLoopReachesTheTruthErrorOnTheEddyCurrentsDecay) {
  expect_loop_reaches_truth({{"eddy_decay", {{TransformKind::Decay, 0.8}}, NAN, 1}});
}

TEST(DiagnoseLong, TheLoopReachesTheTruthErrorOnTheWingsFlex) {
  // The flex alone (0.119 nT; the truth gives 0.126). The next candidate, a slow term of the
  // cabin temperature's voltage (scalar:vol_cabt|lp(665)|sat) that would take up TL's own slow
  // leakage on the held-out lines, lies 99.9999 % within the model's own columns on the fit
  // rows: a stand-in (vol_cabt carries no effect) the loop never adds.
  expect_loop_reaches_truth({{"flex_load", {}, NAN, 1}});
}

TEST(DiagnoseLong, TheLoopReachesTheTruthErrorThroughALagAWireAndAHeater) {
  expect_loop_reaches_truth({{"wire_thermal_lag", {{TransformKind::LowPass, 150.0}}, 0.2, 3}});
}

TEST(Diagnose, NothingIsAcceptedWhereNothingIsHiddenAndTheRestIsWithinNoise) {
  // tl_only: nothing hidden, TL against the reference on its own training lines.
  Model tl_only = test::reference_tl(test::scenario("tl_only").flight);
  tl_only.fit.lines = {1001.02, 1001.04, 1001.10, 1001.12, 1001.14};
  const std::vector<std::pair<std::string, Model>> cases = {
      {"tl_only", tl_only},
      {"noise_only", test::reference_tl(test::scenario("noise_only").flight)}};
  for (const auto& [name, start] : cases) {
    const FlightData& f = test::scenario(name).flight;
    Model m = start;
    fit_model(m, {&f});
    const Diagnosis dx = diagnose(m, f, "mag_1_c");
    size_t accepted = 0;
    for (const auto& c : dx.candidates) accepted += c.accepted;
    std::printf(
        "  %-10s held-out %.3f nT, %zu candidates (%ld terms fitted), %zu accepted; "
        "explainable share %.1f%% +- %.1f%% (floor %.1f%%)\n  verdict: %s\n",
        name.c_str(), dx.baseline_std_nT, dx.candidates.size(), dx.candidates_tried, accepted,
        100 * dx.explainable.share, 100 * dx.explainable.uncertainty,
        100 * dx.explainable.noise_floor, dx.verdict.c_str());
    EXPECT_EQ(accepted, 0u) << name << ": " << dx.candidates.front().term;
    EXPECT_GT(dx.candidates.size(), 200u);
    EXPECT_TRUE(dx.explainable.computed);
    EXPECT_TRUE(dx.explainable.within_noise) << name;
    // "complete" within 1.5x the floor; above it by less than the resolution (tl_only: TL's own
    // misfit, 0.029 nT against a floor of 0.011 nT), "below the resolution", never "structure
    // remains". Noise alone is at its floor.
    ASSERT_TRUE(dx.floor.computed) << name;
    const bool at_floor = dx.floor.residual_std_nT <= 1.5 * dx.floor.floor_nT;
    EXPECT_EQ(dx.verdict.rfind(at_floor ? "complete" : "below the resolution", 0), 0u)
        << dx.verdict;
    if (name == "noise_only") {
      EXPECT_TRUE(at_floor) << dx.verdict;
    }
  }
}

TEST(DiagnoseLong, ASwitchedLoadIsFoundAsAStepOfTheBusCurrent) {
  // A device switched on while the bus current cur_acpwr is above 21 A: a threshold the search
  // writes as field:cur_acpwr|step(?), its level fitted like every '?'. Adding it removes the
  // excess down to what the truth gives.
  const sim::Simulation& s = test::scenario("relay_bus");
  const Model start = test::reference_tl(s.flight);
  const LoopResult r = diagnose_loop(start, s.flight, "mag_1_c", 5, 0.05, {});
  for (const auto& lr : r.rounds)
    std::printf("  round %d %-30s held-out %.3f nT\n", lr.round, lr.added.c_str(),
                lr.heldout_std_nT);
  ASSERT_GE(term_rounds(r).size(), 2u);
  const std::string added = term_rounds(r)[1].added;
  ASSERT_EQ(added.rfind("field:cur_acpwr|step(", 0), 0u) << added;
  EXPECT_NEAR(parameter(added, TransformKind::Step), 21.0, 0.5);  // the truth: 21 A
  const std::vector<double> held = unfitted_lines(start, r.model, s.flight);
  const double truth = truth_std(s, start, held), final_err = std_on(r.model, s.flight, held);
  std::printf("  relay_bus: %s; %.3f nT at the end (the truth gives %.3f)\n", added.c_str(),
              final_err, truth);
  EXPECT_LE(final_err, 1.5 * truth + 0.05);
  EXPECT_LT(r.rounds.back().heldout_std_nT, r.rounds.front().heldout_std_nT);
}

TEST(Diagnose, ARelayChatteringOnItsChannelsNoiseIsFoundToTheSample) {
  // A heater's relay switched while cur_heat is above 0.02 A, a level inside the idle heater's
  // noise (0 +- 0.05 A): whenever the heater is off the relay flips on that noise, a broadband
  // field. The threshold is scanned over the channel's quantiles, where its samples are (an even
  // grid over its range, -0.07 to 5 A, steps over the whole noise band and finds an on/off level
  // near 0.7 A that explains half as much); the step at the true threshold explains most of the
  // held-out error on both halves.
  const sim::Simulation& s = test::scenario("relay_chatter");
  Model m = test::reference_tl(s.flight);
  fit_model(m, {&s.flight});
  DiagnoseOptions o;
  o.full_search = false;
  const Diagnosis dx = diagnose(m, s.flight, "mag_1_c", o);
  ASSERT_FALSE(dx.candidates.empty());
  const Candidate& top = dx.candidates.front();
  std::printf(
      "  relay_chatter: %s, held-out %.3f -> %.3f nT (selection %.1f%%, confirmation %.1f%%)\n",
      top.term.text().c_str(), dx.baseline_std_nT, top.std_after_nT, 100 * top.explained_selection,
      100 * top.explained_confirmation);
  ASSERT_EQ(top.term.text().rfind("field:cur_heat|step(", 0), 0u) << top.term.text();
  EXPECT_NEAR(parameter(top.term.text(), TransformKind::Step), 0.02, 0.005);
  EXPECT_GT(top.explained_selection, 0.8);
  EXPECT_GT(top.explained_confirmation, 0.8);
  EXPECT_TRUE(top.accepted);
}

TEST(Diagnose, ATermItsFitRowsBarelySwitchIsSizedWithItsUncertainty) {
  // A device switched with the pitot heater (3 nT along a fixed direction while sw_pitot_heat is
  // on; it switches every 400 s or so): the band-pass calibration (box and cloverleaf, 210 s)
  // sees it switch once, so its size rests on that one transient. diagnose still names it, and
  // its verdict says how little sizes it: the switch counted, the size's jackknife std a large
  // share of the size, and the advice to size it on another flight or several. The same flight
  // with a reference fit on five lines (the switch's before and after held for minutes,
  // unfiltered) sizes it within a few percent. Both sizes agree with the truth file's within
  // their stds, and the loop's note on an added term (term_support) says the same of it.
  const sim::Simulation& s = test::scenario("rare_switch");
  DiagnoseOptions o;
  o.full_search = false;
  const Model band = test::calibrated_tl(s.flight);
  // The truth's size as a term's is measured: the std of the hidden field beyond what TL's
  // columns and a constant take over the flight.
  double truth_std = 0;
  {
    const Eigen::MatrixXd tl = design_matrix(band, s.flight);
    Eigen::MatrixXd a(tl.rows(), tl.cols() + 1);
    a << tl, s.truth.column("mag_5_uc.hidden.0.relay");
    const Eigen::MatrixXd beyond = beyond_other_columns(a, tl.cols(), 1);
    double sum = 0, sum2 = 0, n = 0;
    for (Eigen::Index i = 0; i < beyond.rows(); ++i)
      if (std::isfinite(beyond(i, 0))) {
        sum += beyond(i, 0);
        sum2 += beyond(i, 0) * beyond(i, 0);
        n += 1;
      }
    truth_std = std::sqrt(sum2 / n - (sum / n) * (sum / n));
  }
  Model reference = test::reference_tl(s.flight);
  reference.fit.lines = {1001.02, 1001.04, 1001.10, 1001.12, 1001.14};
  fit_model(reference, {&s.flight});
  const char* name[2] = {"band-pass on box and cloverleaf", "reference on five lines"};
  const Model* models[2] = {&band, &reference};
  double ratio[2] = {0, 0};
  Diagnosis band_dx;
  for (int k = 0; k < 2; ++k) {
    const Diagnosis dx = diagnose(*models[k], s.flight, "mag_1_c", o);
    ASSERT_FALSE(dx.candidates.empty());
    const Candidate& top = dx.candidates.front();
    std::printf("  %s: %s, size %.3f +- %.3f nT (truth %.3f), %d switch(es) of %s\n    %s\n",
                name[k], top.term.text().c_str(), top.size_nT, top.size_sigma_nT, truth_std,
                top.switches, top.switches_channel.c_str(), dx.verdict.c_str());
    ASSERT_TRUE(top.accepted);
    EXPECT_EQ(top.term.text(), "field:sw_pitot_heat");
    EXPECT_EQ(top.switches_channel, "sw_pitot_heat");
    EXPECT_GE(top.switches, 1);
    EXPECT_LE(top.switches, 3);
    ASSERT_EQ(top.coefficient_sigma.size(), 3u);
    EXPECT_LT(std::abs(top.size_nT - truth_std), 2 * top.size_sigma_nT + 0.02);
    ratio[k] = top.size_sigma_nT / top.size_nT;
    EXPECT_NE(dx.verdict.find("; sw_pitot_heat switched " + std::to_string(top.switches) +
                              " times on the rows that size it: its size, "),
              std::string::npos);
    if (k == 0) band_dx = dx;
    // The loop's note on the same term added to the same model says the same.
    if (k == 0) {
      Model added = band;
      added.add_term("field:sw_pitot_heat");
      fit_model(added, {&s.flight});
      const std::vector<TermSupport> support = term_support(added, band, s.flight);
      ASSERT_EQ(support.size(), 1u);
      std::printf("    the loop's note: %s (size %.3f +- %.3f nT)\n",
                  support_note(support[0]).c_str(), support[0].size_nT, support[0].size_sigma_nT);
      EXPECT_EQ(support[0].switches, top.switches);
      EXPECT_NEAR(support[0].size_nT, top.size_nT, 0.05 * top.size_nT);
    }
  }
  EXPECT_GT(ratio[0], 0.2);
  EXPECT_LT(ratio[1], 0.1);
  // The advice only where the std is a sizeable share of the size.
  EXPECT_NE(band_dx.verdict.find("several flights together (--data A.h5,B.h5)"), std::string::npos);
  Diagnosis told = band_dx;
  told.candidates.front().size_sigma_nT = 0.05 * told.candidates.front().size_nT;
  EXPECT_EQ(diagnose_search::verdict_of(told, 0.03).find("several flights"), std::string::npos);
  EXPECT_NE(diagnose_search::verdict_of(told, 0.03).find("switched"), std::string::npos);
  told.candidates.front().switches = 12;
  EXPECT_EQ(diagnose_search::verdict_of(told, 0.03).find("switched"), std::string::npos);
  told.candidates.front().size_sigma_nT = 0.6 * told.candidates.front().size_nT;
  EXPECT_NE(diagnose_search::verdict_of(told, 0.03).find("is not determined by the rows that"),
            std::string::npos);
}

TEST(DiagnoseLong, ALawNoFormulaWritesIsLearnedAsHingesOfItsChannelAndCarriesOver) {
  // The bus current through a core with a dead band that saturates above it (3 tanh(max(I - 19,
  // 0) / 3)): no closed form of the language writes it exactly. The loop ends with terms of
  // cur_acpwr: a learned law (hinges at its quantiles, marked as a black box in its round and in
  // the model) where no closed form passes, or closed forms that approach it (a step above 19 A,
  // a product with the other bus current). Either way the model carries over to the aircraft's
  // next flight within 1.5x of what the truth gives, and a learned law beats the closed forms
  // alone there.
  sim::Scenario a =
      sim::load_scenario(test::source_dir() + "/config/scenarios/saturation_bus.yaml");
  a.aircraft_seed = 7;  // one aircraft, two flights
  sim::Scenario b = a;
  b.seed = a.seed + 1;
  const sim::Simulation sa = sim::simulate(a, Igrf::installed());
  const sim::Simulation sb = sim::simulate(b, Igrf::installed());
  const Model start = load_model_yaml(test::source_dir() + "/config/models/tl_sim.yaml");
  const LoopResult r = diagnose_loop(start, sa.flight, "mag_1_c", 5, 0.05, {});
  bool learned = false;
  for (const auto& lr : r.rounds) {
    std::printf("  round %d %s%s held-out %.3f nT\n", lr.round, lr.black_box ? "[black box] " : "",
                lr.added.c_str(), lr.heldout_std_nT);
    if (lr.black_box) {
      learned = true;
      EXPECT_NE(lr.added.find("field:cur_acpwr|ramp("), std::string::npos) << lr.added;
    }
  }
  std::printf("  stop: %s\n", r.stop_reason.c_str());
  bool reads_bus = false;
  for (const auto& t : r.model.terms)
    reads_bus =
        reads_bus || (std::find(start.terms.begin(), start.terms.end(), t) == start.terms.end() &&
                      t.text().find("cur_acpwr") != std::string::npos);
  EXPECT_TRUE(reads_bus);
  if (learned) {
    EXPECT_GE(r.model.black_box_terms.size(), 3u);
  }
  for (const auto& t : r.model.black_box_terms) {
    EXPECT_NE(std::find(r.model.terms.begin(), r.model.terms.end(), t), r.model.terms.end()) << t;
  }
  // Scored as scripts/bench_discovery scores: the std on the whole next flight, line means removed.
  const auto std_next = [](const Model& m, const FlightData& f) {
    return evaluate_model(m, f, "mag_1_c").std_nT;
  };
  Model tl_next = start;
  fit_model(tl_next, {&sa.flight});
  const double tl_err = std_next(tl_next, sb.flight);
  // The truth: TL fitted on the first flight with the effect removed, scored on the next one.
  const auto clean = [](const sim::Simulation& s) {
    FlightData f = s.flight;
    Eigen::VectorXd& scalar = f.mutable_column("mag_5_uc");
    for (const auto& name : s.truth.names())
      if (name.rfind("mag_5_uc.hidden.", 0) == 0) scalar -= s.truth.column(name);
    return f;
  };
  const FlightData ca = clean(sa), cb = clean(sb);
  Model oracle = start;
  fit_model(oracle, {&ca});
  const double truth = std_next(oracle, cb);
  const double final_err = std_next(r.model, sb.flight);
  // The same model without its learned law, refitted: what the closed forms alone carry over.
  Model closed_forms = r.model;
  for (const auto& t : r.model.black_box_terms)
    closed_forms.terms.erase(std::find(closed_forms.terms.begin(), closed_forms.terms.end(), t));
  closed_forms.black_box_terms.clear();
  closed_forms.coefficients.resize(0);
  fit_model(closed_forms, {&sa.flight});
  const double closed_err = std_next(closed_forms, sb.flight);
  std::printf(
      "  saturation_bus, next flight: TL %.3f nT, the loop's model %.3f nT (%.3f without its "
      "learned law), the truth %.3f\n",
      tl_err, final_err, closed_err, truth);
  EXPECT_LE(final_err, 1.5 * truth + 0.05);
  if (learned) {
    EXPECT_LT(final_err, closed_err);
  }
  EXPECT_LT(final_err, tl_err);
}

TEST(Diagnose, ATermWithinTheModelsOwnColumnsIsMeasuredSo) {
  // A steady 5 V bus times the field's direction cosines is the permanent term's columns again:
  // on the fit rows all its energy lies within TL's span (Candidate::base_span_share = 1 to
  // rounding). The strobe's wire, switched on and off, adds a direction of its own.
  FlightData f = test::scenario("wire_strobe").flight;
  const Model tl = test::calibrated_tl(f);
  Eigen::VectorXd steady(f.size());
  // A 1e-6 V wander over 10 min: steady, yet not a rail that records its own noise only (those
  // are no source of terms, records_noise_only).
  for (Eigen::Index i = 0; i < f.size(); ++i)
    steady[i] = 5.0 + 1e-6 * std::sin(2 * M_PI * static_cast<double>(i) / 6000.0);
  f.set("vol_steady", steady);
  DiagnoseOptions quick;
  quick.full_search = false;
  quick.explainable_share = false;
  const Diagnosis dx = diagnose(tl, f, "mag_1_c", quick);
  double steady_share = NAN, strobe_share = NAN;
  for (const Candidate& c : dx.candidates) {
    if (c.term == "current:vol_steady" || c.term == "field:vol_steady")
      steady_share = c.base_span_share;
    if (c.term == "current:cur_strb") strobe_share = c.base_span_share;
  }
  std::printf("  within TL's span: steady bus %.9f, strobe's wire %.4f\n", steady_share,
              strobe_share);
  EXPECT_GE(steady_share, 1.0 - 1e-9);
  EXPECT_LE(steady_share, 1.0 + 1e-9);
  EXPECT_LT(strobe_share, 0.5);
  EXPECT_GE(strobe_share, 0.0);
  // Told to add the steady bus's term, the verdict says that the loop never adds it; told to add
  // the strobe's wire, it says nothing of the kind.
  for (const bool steady_bus : {true, false}) {
    Diagnosis told = dx;
    const auto it =
        std::find_if(told.candidates.begin(), told.candidates.end(), [&](const Candidate& c) {
          return steady_bus ? (c.term == "current:vol_steady" || c.term == "field:vol_steady")
                            : c.term == "current:cur_strb";
        });
    ASSERT_NE(it, told.candidates.end()) << steady_bus;
    std::rotate(told.candidates.begin(), it, it + 1);
    Candidate& top = told.candidates.front();
    top.accepted = true;
    top.explained_fraction = 0.3;
    const std::string v = diagnose_search::verdict_of(told, 0.03);
    std::printf("  %s\n", v.c_str());
    EXPECT_EQ(v.rfind("add " + top.term.text() + ":", 0), 0u) << v;
    EXPECT_EQ(within_model_span(top.base_span_share), steady_bus);
    EXPECT_EQ(v.find("never adds it") != std::string::npos, steady_bus) << v;
  }
}

TEST(Diagnose, BadInputsGiveClearMessagesAndConstantChannelsAreSkipped) {
  FlightData f = test::scenario("wire_strobe").flight;
  Model tl = test::calibrated_tl(f);
  f.set("cur_dead", Eigen::VectorXd::Constant(f.size(), 0.0));
  DiagnoseOptions quick;
  quick.full_search = false;
  quick.explainable_share = false;
  const Diagnosis dx = diagnose(tl, f, "mag_1_c", quick);
  bool noted = false;
  for (const auto& n : dx.notes)
    noted = noted || n.find("'cur_dead' is constant") != std::string::npos;
  EXPECT_TRUE(noted);
  FlightData nan_ref = f;
  nan_ref.set("mag_1_c",
              Eigen::VectorXd::Constant(f.size(), std::numeric_limits<double>::quiet_NaN()));
  try {
    diagnose(tl, nan_ref, "mag_1_c", quick);
    FAIL();
  } catch (const Error& e) {
    EXPECT_NE(std::string(e.what()).find("'mag_1_c' holds no finite sample"), std::string::npos);
  }
  Model absent = tl;
  absent.vector = "flux_z";
  try {
    diagnose(absent, f, "mag_1_c", quick);
    FAIL();
  } catch (const Error& e) {
    EXPECT_NE(std::string(e.what()).find("flux_z_x"), std::string::npos) << e.what();
  }
}

TEST(Diagnose, ANetworksChannelsAreSearchedAndJudgedLikeAnyOther) {
  // flex_load: the wing's flex follows the normal acceleration, a motion channel the channels-only
  // search leaves out. A network's attribution that leans on it brings it in; its terms pass the
  // same acceptance rule; a channel with no effect is searched and rejected; a position is
  // never a term.
  const FlightData& f = test::scenario("flex_load").flight;
  Model tl = test::reference_tl(f);
  fit_model(tl, {&f});
  DiagnoseOptions quick;
  quick.full_search = false;
  quick.explainable_share = false;
  quick.joint_selection = false;
  const Diagnosis alone = diagnose(tl, f, "mag_1_c", quick);
  for (const Candidate& c : alone.candidates) {
    const std::vector<std::string> ch = term_channels(c.term);
    EXPECT_EQ(std::find(ch.begin(), ch.end(), "nrml_acc"), ch.end()) << c.term.text();
    EXPECT_EQ(c.network_share, 0.0);
  }
  EXPECT_TRUE(alone.network.empty());
  DiagnoseOptions named = quick;
  named.network_channels = {
      {"vol_bat_1", 0.05}, {"lat", 0.12}, {"cur_strb", 0.28}, {"nrml_acc", 0.55}};
  const Diagnosis dx = diagnose(tl, f, "mag_1_c", named);
  ASSERT_FALSE(dx.candidates.empty());
  const Candidate& top = dx.candidates.front();
  std::printf("  alone: %s %.3f nT (held-out %.3f); with the network: %s %.3f nT\n",
              alone.candidates.front().term.text().c_str(), alone.candidates.front().std_after_nT,
              alone.baseline_std_nT, top.term.text().c_str(), top.std_after_nT);
  EXPECT_EQ(term_channels(top.term), std::vector<std::string>{"nrml_acc"}) << top.term.text();
  EXPECT_TRUE(top.accepted);
  EXPECT_GT(top.explained_fraction, 0.9);
  EXPECT_DOUBLE_EQ(top.network_share, 0.55);
  EXPECT_LT(top.std_after_nT, 0.5 * alone.candidates.front().std_after_nT);
  // The leads in the network's order, at least 10 % each; vol_bat_1 (5 %) is not one.
  ASSERT_EQ(dx.network.size(), 3u);
  EXPECT_EQ(dx.network[0].channel, "nrml_acc");
  EXPECT_TRUE(dx.network[0].searched);
  EXPECT_TRUE(dx.network[0].accepted);
  EXPECT_EQ(dx.network[0].best_term, top.term.text());
  EXPECT_EQ(dx.network[1].channel, "cur_strb");
  EXPECT_TRUE(dx.network[1].searched);
  EXPECT_FALSE(dx.network[1].accepted) << dx.network[1].best_term;
  EXPECT_EQ(term_channels(TermSpec(dx.network[1].best_term)), std::vector<std::string>{"cur_strb"});
  EXPECT_EQ(dx.network[2].channel, "lat");
  EXPECT_FALSE(dx.network[2].searched);
  EXPECT_NE(dx.network[2].why_not.find("position"), std::string::npos);
  EXPECT_TRUE(dx.network[2].best_term.empty());
  // The two leads' product is fitted, with both shares.
  bool product = false;
  for (const Candidate& c : dx.candidates) {
    const std::vector<std::string> ch = term_channels(c.term);
    if (ch.size() == 2 && std::count(ch.begin(), ch.end(), "nrml_acc") &&
        std::count(ch.begin(), ch.end(), "cur_strb")) {
      product = true;
      EXPECT_DOUBLE_EQ(c.network_share, 0.55 + 0.28);
    }
  }
  EXPECT_TRUE(product);
  // The leads are the shares sorted, at least kNetworkMinShare, at most kNetworkChannels.
  const std::vector<NetworkChannel> leads =
      network_leads({{"a", 0.2}, {"b", 0.5}, {"c", 0.099}, {"d", 0.15}, {"e", 0.1}, {"b", 0.4}});
  ASSERT_EQ(leads.size(), 3u);
  EXPECT_EQ(leads[0].channel, "b");
  EXPECT_EQ(leads[1].channel, "a");
  EXPECT_EQ(leads[2].channel, "d");
}

TEST(Diagnose, ARippleOfUnrecordedPhaseIsNeverCompleteAndItsAmplitudeChannelIsNamed) {
  // A 2 Hz ripple whose amplitude follows cur_acpwr and whose phase no channel records: no term
  // can explain it, the residual stays far above its floor, and the verdict says what its power
  // follows.
  const sim::Simulation& s = test::scenario("ripple_bus");
  const LoopResult r =
      diagnose_loop(test::reference_tl(s.flight), s.flight, "mag_1_c", 5, 0.05, {});
  const ResidualFloor& f = r.last.floor;
  std::printf("  held-out %.3f nT, floor %.3f nT; amplitude follows '%s' (rho %.2f)\n  stop: %s\n",
              f.residual_std_nT, f.floor_nT, f.amplitude_channel.c_str(), f.amplitude_correlation,
              r.stop_reason.c_str());
  ASSERT_TRUE(f.computed);
  EXPECT_GT(f.residual_std_nT, 1.5 * f.floor_nT);
  EXPECT_EQ(r.stop_reason.find("complete"), std::string::npos) << r.stop_reason;
  EXPECT_EQ(f.amplitude_channel, "cur_acpwr");
  EXPECT_NE(r.stop_reason.find("its amplitude follows cur_acpwr"), std::string::npos);
  // Nothing of the position channels was added as a term.
  for (const std::string& t : r.model.terms) {
    for (const char* p : {"lat", "lon", "utm_", "ins_lat", "ins_lon", "baro"})
      EXPECT_EQ(t.find(p), std::string::npos) << t;
  }
}

// Two flights of one aircraft (aircraft.seed fixed, other flight seeds), from two_effects: the
// first, a second as validation flight, and the second without the strobe wire (the same aircraft
// with its wiring changed). The start is TL calibrated on the first.
struct ValidationFlights {
  FlightData first, next, rewired;
  Model start;
};

const ValidationFlights& validation_flights() {
  static const ValidationFlights v = [] {
    sim::Scenario a = sim::load_scenario(test::source_dir() + "/config/scenarios/two_effects.yaml");
    a.aircraft_seed = 7;
    sim::Scenario b = a;
    b.seed = a.seed + 1;
    sim::Scenario c = b;
    c.hidden.erase(c.hidden.begin());  // the wire
    ValidationFlights out;
    out.first = sim::simulate(a, Igrf::installed()).flight;
    out.next = sim::simulate(b, Igrf::installed()).flight;
    out.rewired = sim::simulate(c, Igrf::installed()).flight;
    out.start = test::calibrated_tl(out.first);
    return out;
  }();
  return v;
}

TEST(Diagnose, AValidationFlightKeepsOnlyTermsThatCarryOverAndSaysWhy) {
  // On a validation flight where the strobe wire is not there, the wire's term raises the error
  // there: it is refused, with the reason, and the final model is never worse on the validation
  // flight than the start. (The same aircraft's next flight keeps both: DiagnoseLong.)
  const ValidationFlights& v = validation_flights();
  const LoopResult rewired =
      diagnose_loop(v.start, v.first, "mag_1_c", 5, 0.05, {}, {}, &v.rewired);
  std::printf("  validation without the wire:");
  for (const auto& lr : rewired.rounds)
    std::printf(" [%s %.3f nT]", lr.round ? lr.added.c_str() : "start", lr.validation_std_nT);
  std::printf("\n  stop: %s\n", rewired.stop_reason.c_str());
  for (const auto& t : rewired.model.terms) EXPECT_NE(t, "current:cur_strb");
  // The refusal of a term of the wire's current and its reason: in the round that kept another
  // term, or in the stop.
  const std::string reason = "the error on the validation flight would not fall";
  std::string refusals = rewired.stop_reason;
  bool wire_refused = rewired.stop_reason.find("cur_strb") != std::string::npos &&
                      rewired.stop_reason.find(reason) != std::string::npos;
  for (const auto& lr : rewired.rounds)
    for (const auto& [term, why] : lr.rejected) {
      refusals += "; " + term + ": " + why;
      wire_refused =
          wire_refused || (term.find("cur_strb") != std::string::npos && why.find(reason) == 0);
    }
  EXPECT_TRUE(wire_refused) << refusals;
  EXPECT_LE(rewired.rounds.back().validation_std_nT, rewired.rounds.front().validation_std_nT);
}

TEST(DiagnoseLong, AValidationFlightOfTheSameAircraftKeepsTheTermsThatCarryOver) {
  // The wire and the lag are kept because they lower the error on the other flight too.
  const ValidationFlights& v = validation_flights();
  const LoopResult same = diagnose_loop(v.start, v.first, "mag_1_c", 5, 0.05, {}, {}, &v.next);
  std::printf("  validation on the next flight:");
  for (const auto& lr : same.rounds)
    std::printf(" [%s %.3f nT]", lr.round ? lr.added.c_str() : "start", lr.validation_std_nT);
  std::printf("\n");
  ASSERT_GE(term_rounds(same).size(), 3u) << same.stop_reason;
  EXPECT_EQ(term_rounds(same)[1].added, "lag:0.3");
  EXPECT_EQ(term_rounds(same)[2].added, "current:cur_strb");
  for (size_t k = 1; k < same.rounds.size(); ++k)
    EXPECT_LT(same.rounds[k].validation_std_nT, same.rounds[k - 1].validation_std_nT);
  EXPECT_LT(same.rounds.back().validation_std_nT, 0.1 * same.rounds.front().validation_std_nT);
}

TEST(Diagnose, AProductOfTwoChannelsThatExplainNothingAloneIsFoundByTheScreen) {
  // b ∝ pitch_rate · roll_rate: both zero-mean, so no single-channel term predicts it and the
  // strongest single channels are not its factors. Only the screen over every pair finds it.
  const sim::Simulation& s = test::scenario("product_rates");
  const Model start = test::reference_tl(s.flight);
  const LoopResult r = diagnose_loop(start, s.flight, "mag_1_c", 5, 0.05, {});
  const std::vector<double> held = unfitted_lines(start, r.model, s.flight);
  const double truth = truth_std(s, start, held);
  const double final_err = std_on(r.model, s.flight, held);
  std::printf("  product_rates: %zu rounds, %s; %.3f nT (the truth gives %.3f)\n",
              r.rounds.size() - 1,
              term_rounds(r).size() > 1 ? term_rounds(r)[1].added.c_str() : "-", final_err, truth);
  ASSERT_GE(term_rounds(r).size(), 2u) << r.stop_reason;
  const std::string added = term_rounds(r)[1].added;
  EXPECT_TRUE(added == "field:pitch_rate*roll_rate" || added == "field:roll_rate*pitch_rate")
      << added;
  EXPECT_LE(final_err, 1.5 * truth + 0.05);
}

// Two wires that act together: a supply and its return, on two pumps switched independently
// during the calibration maneuvers and, on the survey, by one schedule with the second 3 s
// late. On the survey their fields mostly cancel, so each wire alone, sized on the maneuvers,
// makes the held-out lines worse; together they are exact. The loop adds them as a pair and
// names both channels, nothing else.
TEST(Diagnose, TwoWiresThatOnlyHelpTogetherAreAddedTogether) {
  FlightData f = test::scenario("tl_only").flight;
  const std::vector<double> maneuvers = test::calibrated_tl(f).fit.lines;
  const Eigen::VectorXd t = f.tt();
  const Eigen::VectorXd line = f.column("line");
  const auto on = [](double t_s, double period_s) {
    return std::fmod(t_s, period_s) < 0.5 * period_s ? 2.0 : 0.0;
  };
  Eigen::VectorXd a(t.size()), b(t.size());
  for (Eigen::Index i = 0; i < t.size(); ++i) {
    const bool maneuver = std::find(maneuvers.begin(), maneuvers.end(), line[i]) != maneuvers.end();
    a[i] = on(t[i], 40.0);
    b[i] = maneuver ? on(t[i] + 7.0, 26.0) : on(t[i] - 3.0, 40.0);
  }
  f.set("cur_pump_a", a);
  f.set("cur_pump_b", b);
  Model wires = test::calibrated_tl(f);
  wires.terms = {"current:cur_pump_a", "current:cur_pump_b"};
  const Eigen::MatrixXd cols = design_matrix(wires, f);
  ASSERT_EQ(cols.cols(), 6);
  Eigen::VectorXd c(6);
  c << 0.8, -0.5, 1.1, -0.76, 0.475, -1.045;  // nT per A per unit of field: b's is -0.95 a's
  const Eigen::VectorXd effect = cols * c;
  f.mutable_column("mag_5_uc") += effect;
  const Model start = test::calibrated_tl(f);
  Model truth_model = start;
  truth_model.terms.insert(truth_model.terms.end(), wires.terms.begin(), wires.terms.end());
  truth_model.coefficients.resize(0);
  fit_model(truth_model, {&f});
  const LoopResult r = diagnose_loop(start, f, "mag_1_c", 5, 0.05, {});
  const std::vector<double> held = unfitted_lines(start, r.model, f);
  Model alone_a = start, alone_b = start;
  alone_a.add_term("current:cur_pump_a");
  alone_b.add_term("current:cur_pump_b");
  for (Model* m : {&alone_a, &alone_b}) {
    m->coefficients.resize(0);
    fit_model(*m, {&f});
  }
  const double tl = std_on(start, f, held), truth = std_on(truth_model, f, held);
  const double final_err = std_on(r.model, f, held);
  std::printf(
      "  two wires: TL %.3f nT, wire a alone %.3f, wire b alone %.3f, both %.3f; loop %.3f:", tl,
      std_on(alone_a, f, held), std_on(alone_b, f, held), truth, final_err);
  for (const auto& lr : r.rounds)
    if (lr.round > 0) std::printf(" [%s%s]", lr.together ? "together " : "", lr.added.c_str());
  std::printf("\n  %s\n", r.stop_reason.c_str());
  // The premise: each alone is worse than TL on the held-out lines.
  EXPECT_GT(std_on(alone_a, f, held), tl);
  EXPECT_GT(std_on(alone_b, f, held), tl);
  EXPECT_LE(final_err, 1.5 * truth + 0.05);
  std::set<std::string> channels;
  for (const auto& term : r.model.terms) {
    const auto e = parse_expr_term(term);
    if (e)
      for (const auto& src : e->signal().sources) channels.insert(src);
  }
  EXPECT_EQ(channels, (std::set<std::string>{"cur_pump_a", "cur_pump_b"}));
  // One term at a time, the loop finds neither.
  DiagnoseOptions one_at_a_time;
  one_at_a_time.joint_steps = false;
  const LoopResult single = diagnose_loop(start, f, "mag_1_c", 5, 0.05, one_at_a_time);
  EXPECT_GT(std_on(single.model, f, held), 1.5 * truth + 0.05);
}

// A bus current and the two loads it feeds: the bus reads the sum of the loads' currents (and
// its sensor's own noise), and the two loads' wires carry the effect, each with its own
// direction. The bus alone explains more than either load alone, so one term at a time takes
// the bus first and then one load, which together span the same columns: the model carries
// over but names a channel that carries no effect. Chosen as a set, the two loads are exact
// and each is needed: the loop adds them together and names them alone.
// start: TL calibrated on that flight; truth: TL plus both wires.
struct BusFlight {
  FlightData flight;
  Model start, truth;
};

const BusFlight& bus_flight() {
  static const BusFlight flight = [] {
    FlightData f = test::scenario("tl_only").flight;
    const Eigen::VectorXd t = f.tt();
    const auto on = [](double t_s, double period_s, double phase_s) {
      return std::fmod(t_s + phase_s, period_s) < 0.5 * period_s ? 1.5 : 0.0;
    };
    std::mt19937 rng(7);
    std::normal_distribution<double> noise(0.0, 0.05);
    Eigen::VectorXd a(t.size()), b(t.size()), bus(t.size());
    for (Eigen::Index i = 0; i < t.size(); ++i) {
      a[i] = on(t[i], 37.0, 0.0);
      b[i] = on(t[i], 23.0, 5.0);
      bus[i] = a[i] + b[i] + noise(rng);
    }
    f.set("cur_load_a", a);
    f.set("cur_load_b", b);
    f.set("cur_bus", bus);
    Model wires = test::calibrated_tl(f);
    wires.terms = {"current:cur_load_a", "current:cur_load_b"};
    const Eigen::MatrixXd cols = design_matrix(wires, f);
    if (cols.cols() != 6) throw std::logic_error("two wires give 6 columns");
    Eigen::VectorXd c(6);
    c << 0.8, -0.5, 1.1, 0.7, 0.3, 0.9;  // nT per A per unit of field
    f.mutable_column("mag_5_uc") += cols * c;
    BusFlight out;
    out.start = test::calibrated_tl(f);
    out.truth = out.start;
    out.truth.terms.insert(out.truth.terms.end(), wires.terms.begin(), wires.terms.end());
    out.truth.coefficients.resize(0);
    fit_model(out.truth, {&f});
    out.flight = std::move(f);
    return out;
  }();
  return flight;
}

std::set<std::string> channels_of(const Model& m) {
  std::set<std::string> out;
  for (const auto& term : m.terms) {
    const auto e = parse_expr_term(term);
    if (e)
      for (const auto& src : e->signal().sources) out.insert(src);
  }
  return out;
}

TEST(DiagnoseLong, TheLoadsOfABusAreChosenTogetherOverTheBus) {
  const BusFlight& b = bus_flight();
  const FlightData& f = b.flight;
  const Model& start = b.start;
  // The first diagnosis: the bus ranks first alone; the set is the two loads, stable.
  const Diagnosis dx = diagnose(start, f, "mag_1_c");
  ASSERT_FALSE(dx.candidates.empty());
  EXPECT_EQ(dx.candidates.front().channel, "cur_bus") << dx.candidates.front().term;
  ASSERT_EQ(dx.joint.terms.size(), 2u) << "pool " << dx.joint.pool_size;
  std::set<std::string> joint_channels;
  for (const TermSpec& term : dx.joint.terms)
    for (const auto& src : term.expr()->signal().sources) joint_channels.insert(src);
  EXPECT_EQ(joint_channels, (std::set<std::string>{"cur_load_a", "cur_load_b"}));
  std::printf(
      "  first diagnosis: %s first (%.3f nT held out); chosen together (pool %d, %.0f%% "
      "of the resamplings): %.3f nT, each alone %.3f and %.3f nT\n",
      dx.joint.best_single.c_str(), dx.joint.best_single_std_nT, dx.joint.pool_size,
      100 * dx.joint.stability, dx.joint.heldout_std_nT, dx.joint.alone_std_nT[0],
      dx.joint.alone_std_nT[1]);
  EXPECT_GE(dx.joint.stability, kJointStability);
  EXPECT_LT(dx.joint.heldout_std_nT, dx.joint.best_single_std_nT);
  {  // The CLI says so, and writes it in the JSON.
    const std::string dir = test::temp_dir("joint");
    write_flight_h5(f, dir + "/f.h5");
    save_model_yaml(start, dir + "/start.yaml");
    std::string out;
    ASSERT_EQ(test::run(test::cli() + " diagnose --data " + dir + "/f.h5 --model " + dir +
                            "/start.yaml --json " + dir + "/d.json",
                        &out),
              0)
        << out;
    EXPECT_NE(out.find("chosen together (2 terms"), std::string::npos) << out;
    const nlohmann::json j = nlohmann::json::parse(std::ifstream(dir + "/d.json"));
    ASSERT_TRUE(j.contains("joint_set")) << j.dump();
    EXPECT_EQ(j["joint_set"]["terms"].size(), 2u);
    EXPECT_EQ(j["joint_set"]["best_single"], dx.joint.best_single);
    EXPECT_NEAR(j["joint_set"]["heldout_std_nT"].get<double>(), dx.joint.heldout_std_nT, 1e-9);
  }
  const LoopResult r = diagnose_loop(start, f, "mag_1_c", 5, 0.05, {});
  const std::vector<double> held = unfitted_lines(start, r.model, f);
  const double tl = std_on(start, f, held), truth = std_on(b.truth, f, held);
  const double final_err = std_on(r.model, f, held);
  std::printf("  bus and loads: TL %.3f nT, both loads %.3f; loop %.3f:", tl, truth, final_err);
  for (const auto& lr : r.rounds)
    if (lr.round > 0) std::printf(" [%s%s]", lr.together ? "together " : "", lr.added.c_str());
  std::printf("\n");
  EXPECT_LE(final_err, 1.5 * truth + 0.05);
  EXPECT_EQ(channels_of(r.model), (std::set<std::string>{"cur_load_a", "cur_load_b"}));
  ASSERT_GE(term_rounds(r).size(), 2u);
  EXPECT_TRUE(term_rounds(r)[1].together);
}

TEST(DiagnoseLong, OneTermAtATimeTakesTheBusFirst) {
  // The premise of the joint selection: without it the loop's first round takes the bus's
  // current, which carries the loads' sum; the loads' own terms come after it, and the backward
  // pass takes the bus out once they are written.
  const BusFlight& b = bus_flight();
  DiagnoseOptions no_joint;
  no_joint.joint_selection = false;
  const LoopResult greedy = diagnose_loop(b.start, b.flight, "mag_1_c", 5, 0.05, no_joint);
  const std::vector<double> held = unfitted_lines(b.start, greedy.model, b.flight);
  std::printf("  without the joint selection %.3f nT:", std_on(greedy.model, b.flight, held));
  for (const auto& lr : greedy.rounds)
    if (lr.round > 0) std::printf(" [%s]", lr.added.c_str());
  std::printf("\n");
  ASSERT_GE(greedy.rounds.size(), 2u);
  EXPECT_EQ(greedy.rounds[1].added, "current:cur_bus");
  EXPECT_FALSE(channels_of(greedy.model).count("cur_bus"));
}

// A channel the flight cannot tell from another: a lamp's wire carries the effect, and a monitor
// of the same lamp records its current again with 0.03 A of noise. Either term lowers the error
// alike, so the loop keeps one and names the other as its look-alike (rounds table and JSON); a
// pump switched on its own pattern, which carries no effect, is not named. (A channel told apart
// has no look-alike: DiagnoseLong.TwoHiddenEffectsAreFoundInTwoRoundsAndReachTheFloor.)
TEST(DiagnoseLong, AChannelTheFlightCannotTellApartIsNamedAsALookAlike) {
  FlightData f = test::scenario("tl_only").flight;
  const Eigen::VectorXd t = f.tt();
  std::mt19937 rng(11);
  std::normal_distribution<double> noise(0.0, 0.03);
  Eigen::VectorXd lamp(t.size()), monitor(t.size()), pump(t.size());
  for (Eigen::Index i = 0; i < t.size(); ++i) {
    lamp[i] = std::fmod(t[i], 37.0) < 18.5 ? 1.5 : 0.0;
    monitor[i] = lamp[i] + noise(rng);
    pump[i] = std::fmod(t[i] + 5.0, 23.0) < 11.5 ? 2.0 : 0.0;
  }
  f.set("cur_lamp", lamp);
  f.set("cur_pump", pump);
  Model wire = test::calibrated_tl(f);
  wire.terms = {"current:cur_lamp"};
  const Eigen::MatrixXd cols = design_matrix(wire, f);
  ASSERT_EQ(cols.cols(), 3);
  f.mutable_column("mag_5_uc") += cols * Eigen::Vector3d(0.9, -0.6, 1.2);
  f.set("cur_lamp_mon", monitor);
  const Model start = test::calibrated_tl(f);
  const auto fields = [](const std::string& term) {
    const std::vector<std::string> v = TermSpec(term).term().required_fields();
    return std::set<std::string>(v.begin(), v.end());
  };
  // Through the CLI: one of the two kept, the other named beside it.
  const std::string dir = test::temp_dir("look_alike");
  write_flight_h5(f, dir + "/f.h5");
  save_model_yaml(start, dir + "/start.yaml");
  std::string out;
  ASSERT_EQ(test::run(test::cli() + " diagnose --apply --rounds 1 --data " + dir +
                          "/f.h5 --model " + dir + "/start.yaml --truth mag_1_c --out " + dir +
                          "/d.yaml --json " + dir + "/d.json",
                      &out),
            0)
      << out;
  const nlohmann::json j = nlohmann::json::parse(std::ifstream(dir + "/d.json"));
  ASSERT_GE(j["rounds"].size(), 2u) << j.dump();
  const nlohmann::json& r1 = j["rounds"][1];
  std::set<std::string> named = fields(r1["added"].get<std::string>());
  ASSERT_EQ(named.size(), 1u);
  const std::string kept = *named.begin();
  EXPECT_TRUE(kept == "cur_lamp" || kept == "cur_lamp_mon") << kept;
  std::printf("  kept %s (held-out %.3f nT); look-alikes:", r1["added"].get<std::string>().c_str(),
              r1["heldout_std_nT"].get<double>());
  for (const auto& la : r1["look_alikes"]) {
    std::printf(" %s %.3f nT", la["term"].get<std::string>().c_str(),
                la["heldout_std_nT"].get<double>());
    for (const std::string& x : fields(la["term"].get<std::string>())) named.insert(x);
  }
  std::printf("\n");
  EXPECT_TRUE(named.count("cur_lamp") && named.count("cur_lamp_mon")) << out;
  EXPECT_FALSE(named.count("cur_pump")) << out;
  EXPECT_NE(out.find("look-alike "), std::string::npos) << out;
  EXPECT_NE(out.find("these flights cannot tell its channel from"), std::string::npos) << out;
  // The channels a wire's field may scale with unseen: a key in every round, each channel with
  // its relative std (the lamp's 28 V supply is not recorded here: none may be named).
  ASSERT_TRUE(r1["steady_factors"].is_array()) << r1.dump();
  for (const auto& f : r1["steady_factors"]) {
    EXPECT_LT(f["relative_std"].get<double>(), 0.1) << f.dump();
    EXPECT_EQ(f["channel"].get<std::string>().rfind("cur_lamp", 0), std::string::npos) << f.dump();
  }
}

// Which channels are states of the aircraft (a slow term, a grown chain or a learned law may
// follow them): currents, voltages and any recorded channel that is not motion, air data,
// position, a magnetometer or bookkeeping.
TEST(Diagnose, EveryRecordedStateOfTheAircraftCanBeAFactor) {
  for (const char* state :
       {"cur_strb", "vol_bat_1", "flap_deg", "eng_rpm", "oat_degC", "valve_fuel", "sw_pitot_heat"})
    EXPECT_TRUE(is_aircraft_state(state)) << state;
  for (const char* other :
       {"ins_vn", "ins_pitch", "roll_rate", "pitch_rt", "nrml_acc", "tas", "total_p", "static_p",
        "lat", "utm_x", "baro", "mag_1_c", "flux_c_x", "diurnal", "tt", "line", "ogs_mag"})
    EXPECT_FALSE(is_aircraft_state(other)) << other;
  EXPECT_TRUE(is_motion_channel("ins_roll"));
  EXPECT_FALSE(is_motion_channel("flap_deg"));
}

// Effects through recorded states that are neither currents nor voltages: a switched light's
// wire whose field grows with the flap setting (a product of a current and a slowly stepping
// surface position), and the magnetometer's reading drifting with its electronics' temperature
// (slow: only the slow stage, which follows states of the aircraft, can size it). The loop
// finds each, names its channels and nothing else, and reaches the true terms' error.
struct StateCase {
  std::string term;
  double gain;
  std::set<std::string> channels;
};

void expect_state_effect_found(const StateCase& c) {
  const FlightData base = test::scenario("tl_only").flight;
  const Eigen::VectorXd t = base.tt();
  Eigen::VectorXd light(t.size()), flap(t.size()), temp(t.size());
  for (Eigen::Index i = 0; i < t.size(); ++i) {
    light[i] = std::fmod(t[i], 30.0) < 15.0 ? 1.5 : 0.0;
    flap[i] = 10.0 * std::floor(std::fmod(t[i] / 170.0, 3.0));  // 0, 10, 20 deg
    temp[i] = 20.0 + 4.0 * std::sin(2 * M_PI * t[i] / 500.0);
  }
  FlightData f = base;
  f.set("cur_light", light);
  f.set("flap_deg", flap);
  f.set("tmp_sensor_degC", temp);
  Model effect = test::calibrated_tl(f);
  effect.terms = {c.term};
  const Eigen::MatrixXd cols = design_matrix(effect, f);
  Eigen::VectorXd coef = Eigen::VectorXd::Constant(cols.cols(), c.gain);
  if (cols.cols() == 3) coef << c.gain, -0.6 * c.gain, 0.8 * c.gain;
  f.mutable_column("mag_5_uc") += cols * coef;
  const Model start = test::calibrated_tl(f);
  Model truth_model = start;
  truth_model.add_term(c.term);
  if (c.term.rfind("scalar:", 0) == 0) truth_model.add_slow_term(c.term, "mag_1_c");
  truth_model.coefficients.resize(0);
  fit_model(truth_model, {&f});
  const LoopResult r = diagnose_loop(start, f, "mag_1_c", 5, 0.05, {});
  const std::vector<double> held = unfitted_lines(start, r.model, f);
  const double tl = std_on(start, f, held), truth = std_on(truth_model, f, held);
  const double final_err = std_on(r.model, f, held);
  std::set<std::string> named;
  for (const auto& term : r.model.terms) {
    if (std::find(start.terms.begin(), start.terms.end(), term) != start.terms.end()) continue;
    const auto e = parse_expr_term(term);
    if (e)
      for (const auto& src : e->signal().sources) named.insert(src);
  }
  std::printf("  %s: TL %.3f nT, true term %.3f; loop %.3f:", c.term.c_str(), tl, truth, final_err);
  for (const auto& lr : r.rounds)
    if (lr.round > 0) std::printf(" [%s]", lr.added.c_str());
  std::printf("\n");
  EXPECT_LT(final_err, 0.5 * tl) << c.term;
  EXPECT_LE(final_err, 1.5 * truth + 0.05) << c.term;
  EXPECT_EQ(named, c.channels) << c.term << ": " << r.stop_reason;
  // The temperature's drift is sized by the slow stage.
  if (c.term.rfind("scalar:", 0) == 0) {
    EXPECT_EQ(r.model.slow_terms.size(), 1u);
  }
}

TEST(Diagnose, EffectsOfNonElectricalStatesAreFoundAndNamed) {
  // The light's wire times the flap setting (the temperature's drift: DiagnoseLong).
  expect_state_effect_found({"field:cur_light*flap_deg", 0.1, {"cur_light", "flap_deg"}});
}

TEST(DiagnoseLong, ADriftWithTheSensorsTemperatureIsSizedByTheSlowStageAndNamed) {
  expect_state_effect_found({"scalar:tmp_sensor_degC|lp(60)", 0.5, {"tmp_sensor_degC"}});
}

TEST(Diagnose, HysteresisIsFoundAsAPlayOfTheCurrentWithItsWidth) {
  // A soft-iron part magnetised by the bus current with a play of 1.5 A: field:cur_acpwr|play(?)
  // is searched for every current, and the fit estimates the half-width.
  const sim::Simulation& s = test::scenario("hysteresis_bus");
  const Model start = test::reference_tl(s.flight);
  const LoopResult r = diagnose_loop(start, s.flight, "mag_1_c", 5, 0.05, {});
  const std::vector<double> held = unfitted_lines(start, r.model, s.flight);
  const double truth = truth_std(s, start, held), final_err = std_on(r.model, s.flight, held);
  ASSERT_GE(term_rounds(r).size(), 2u) << r.stop_reason;
  const std::string added = term_rounds(r)[1].added;
  std::printf("  hysteresis_bus: %s; %.3f nT (the truth gives %.3f)\n", added.c_str(), final_err,
              truth);
  ASSERT_EQ(added.rfind("field:cur_acpwr|play(", 0), 0u) << added;
  EXPECT_NEAR(std::stod(added.substr(added.find('(') + 1)), 1.5, 0.15);
  EXPECT_LE(final_err, 1.5 * truth + 0.05);
}

TEST(Diagnose, AFreePlayWidthWrittenInTheModelIsEstimatedByTheFit) {
  // The same part, its term written by the user as field:cur_acpwr|play(?): fit_model scans the
  // half-width over the current's range and writes the estimate into the term (1.5 A simulated).
  const sim::Simulation& s = test::scenario("hysteresis_bus");
  Model m = test::reference_tl(s.flight);
  ASSERT_TRUE(m.add_term("field:cur_acpwr|play(?)"));
  m.coefficients.resize(0);
  fit_model(m, {&s.flight});
  const auto it = std::find_if(m.terms.begin(), m.terms.end(), [](const std::string& t) {
    return t.rfind("field:cur_acpwr|play(", 0) == 0;
  });
  ASSERT_NE(it, m.terms.end());
  EXPECT_NEAR(std::stod(it->text().substr(it->text().find('(') + 1)), 1.5, 0.15) << *it;
}

}  // namespace
}  // namespace magcomp
