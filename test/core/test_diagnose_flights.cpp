// The loop over several flights of one aircraft: an effect the first flight never shows on its
// calibration rows is found on another flight, fitted on both, and carries over to a third.
#include <gtest/gtest.h>

#include <cmath>
#include <set>

#include "magcomp/core/diagnose/diagnose_loop.h"
#include "magcomp/core/diagnose/term_support.h"
#include "magcomp/core/evaluate/evaluation.h"
#include "magcomp/core/fit/model_fit.h"
#include "magcomp/core/model/terms_expr.h"
#include "magcomp/core/sim/scenario.h"
#include "magcomp/core/sim/simulator.h"
#include "test_util.h"

namespace magcomp {
namespace {

// A flight of aircraft 77 (config/scenarios/random_base.yaml, flight seed `seed`) with a pump
// on a recorded current cur_pump (2 A, switched in a square wave of `period_s`) whose wire adds
// 0.8, -0.5, 1.1 nT/A along the field's direction cosines (the term current:cur_pump); with
// `idle_on_calibration`, the pump is off on the calibration lines.
FlightData pump_flight(unsigned seed, double period_s, bool idle_on_calibration,
                       const std::vector<double>& calibration_lines) {
  sim::Scenario s = sim::load_scenario(test::source_dir() + "/config/scenarios/random_base.yaml");
  s.aircraft_seed = 77;
  s.seed = seed;
  FlightData f = sim::simulate(s, Igrf::installed()).flight;
  const Eigen::VectorXd t = f.tt();
  const auto line = f.column("line");
  Eigen::VectorXd pump(t.size());
  for (Eigen::Index i = 0; i < t.size(); ++i) {
    const bool calibration = std::find(calibration_lines.begin(), calibration_lines.end(),
                                       line[i]) != calibration_lines.end();
    pump[i] = idle_on_calibration && calibration           ? 0.0
              : std::fmod(t[i], period_s) < 0.5 * period_s ? 2.0
                                                           : 0.0;
  }
  f.set("cur_pump", pump);
  Model wire = load_model_yaml(test::source_dir() + "/config/models/tl_sim.yaml");
  wire.terms = {"current:cur_pump"};
  const Eigen::MatrixXd cols = design_matrix(wire, f);
  f.mutable_column("mag_5_uc") += cols * Eigen::Vector3d(0.8, -0.5, 1.1);
  return f;
}

bool reads(const Model& m, const std::string& channel) {
  for (const auto& t : m.terms) {
    const auto e = parse_expr_term(t);
    if (!e) continue;
    for (const auto& src : e->signal().sources)
      if (src == channel) return true;
  }
  return false;
}

TEST(DiagnoseFlightsLong, AnEffectTheFirstFlightNeverCalibratesIsFoundOnTheSecondAndCarriesOver) {
  const Model tl = load_model_yaml(test::source_dir() + "/config/models/tl_sim.yaml");
  const std::vector<double>& cal = tl.fit.lines;
  const FlightData a = pump_flight(11, 40.0, true, cal);
  const FlightData b = pump_flight(12, 34.0, false, cal);
  const FlightData next = pump_flight(13, 46.0, false, cal);
  DiagnoseOptions options;
  options.full_search = false;  // the electrical channels: the effect is one of them
  // The truth: TL plus the pump's own term, fitted on the two flights.
  Model truth = tl;
  truth.add_term("current:cur_pump");
  fit_model(truth, {&a, &b});
  const double truth_next = evaluate_model(truth, next, "mag_1_c").std_nT;
  Model start = tl;
  fit_model(start, {&a});
  const double tl_next = evaluate_model(start, next, "mag_1_c").std_nT;

  // The first flight alone: its calibration rows never see the pump, so no term of it can be
  // sized there, whatever the residual shows.
  DiagnoseOptions on_calibration = options;
  on_calibration.slow_terms_on_lines = false;
  const LoopResult one = diagnose_loop(start, a, "mag_1_c", 2, 0.05, on_calibration);
  const double one_next = evaluate_model(one.model, next, "mag_1_c").std_nT;
  // Its held-out lines do see it: with slow terms sized there too (cross-fitted, once nothing
  // passes sized on the calibration rows), the first flight alone finds the pump.
  const LoopResult lines = diagnose_loop(start, a, "mag_1_c", 2, 0.05, options);
  const double lines_next = evaluate_model(lines.model, next, "mag_1_c").std_nT;
  std::string lines_kept;
  for (const auto& t : lines.model.slow_terms) lines_kept += " " + t;
  std::printf("  first flight, slow terms sized on its lines too: %.3f nT; slow terms%s\n",
              lines_next, lines_kept.c_str());
  EXPECT_TRUE(reads(lines.model, "cur_pump"));
  EXPECT_LE(lines_next, 1.5 * truth_next + 0.05);
  EXPECT_FALSE(lines.model.fit.slow_lines.empty());
  // Both flights: the second's calibration rows see it.
  const LoopResult both = diagnose_loop(tl, {&a, &b}, "mag_1_c", 2, 0.05, options);
  const double both_next = evaluate_model(both.model, next, "mag_1_c").std_nT;
  std::printf(
      "  next flight: TL %.3f nT, truth %.3f; loop on the first flight %.3f, on both %.3f\n",
      tl_next, truth_next, one_next, both_next);
  for (const auto& lr : both.rounds) {
    std::printf("  round %d %s: held-out %.3f nT (per flight", lr.round, lr.added.c_str(),
                lr.heldout_std_nT);
    for (double v : lr.flight_heldout_std_nT) std::printf(" %.3f", v);
    std::printf(")\n");
  }
  std::printf("  stop: %s\n", both.stop_reason.c_str());

  EXPECT_FALSE(reads(one.model, "cur_pump"));
  EXPECT_GT(one_next, 3.0 * truth_next);
  EXPECT_TRUE(reads(both.model, "cur_pump"));
  EXPECT_LE(both_next, 1.5 * truth_next + 0.05);
  EXPECT_LT(both_next, 0.5 * tl_next);
  // Every round's held-out error is given per flight, and each flight's falls where the pump is
  // added.
  ASSERT_GE(both.rounds.size(), 2u);
  for (const auto& lr : both.rounds) ASSERT_EQ(lr.flight_heldout_std_nT.size(), 2u);
  EXPECT_LT(both.rounds.back().flight_heldout_std_nT[0],
            0.5 * both.rounds.front().flight_heldout_std_nT[0]);
  EXPECT_LT(both.rounds.back().flight_heldout_std_nT[1],
            0.5 * both.rounds.front().flight_heldout_std_nT[1]);
  EXPECT_EQ(both.last_flights.size(), 2u);

  // The support: the pump never switched on the first flight's calibration rows, often on the
  // second's, and the note says so for the first alone.
  const std::vector<TermSupport> on_a = term_support(both.model, tl, a);
  const std::vector<TermSupport> on_ab = term_support(both.model, tl, {&a, &b});
  for (size_t k = 0; k < on_ab.size(); ++k) {
    if (on_ab[k].channel != "cur_pump") continue;
    EXPECT_EQ(on_a[k].switches, 0);
    EXPECT_GE(on_ab[k].switches, 10);
    EXPECT_NE(support_note(on_a[k]).find("cur_pump switched 0 times"), std::string::npos);
    EXPECT_EQ(support_note(on_ab[k]), "");
  }
}

}  // namespace
}  // namespace magcomp
