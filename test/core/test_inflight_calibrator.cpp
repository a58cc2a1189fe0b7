// In-flight calibration: the batch solution equals `calibrate`; the recursive one converges to it.
#include <gtest/gtest.h>

#include "magcomp/core/evaluate/flight_conditions.h"
#include "magcomp/core/fit/inflight_calibrator.h"
#include "scenario_cache.h"

namespace magcomp {
namespace {

/// The shipped TL model plus the strobe current's term, uncalibrated.
Model strobe_template() {
  Model m = load_model_yaml(test::source_dir() + "/config/models/tl_sim.yaml");
  m.add_term("current:cur_strb");
  return m;
}

TEST(InflightCalibrator, BatchEqualsCalibrateAndRlsConvergesTowardIt) {
  const FlightData& f = test::scenario("wire_strobe").flight;
  const Model templ = strobe_template();
  const Model cli = test::calibrated_tl(f, {"current:cur_strb"});
  InflightCalibrator cal(templ, 1.0);
  const auto in_box = f.select(templ.fit.lines, templ.fit.windows);
  std::vector<bool> flag(static_cast<size_t>(f.size()), false);
  for (auto i : in_box) flag[static_cast<size_t>(i)] = true;
  std::vector<std::pair<Eigen::Index, double>> history;  // (samples seen, rls error std)
  for (Eigen::Index i = 0; i < f.size(); ++i) {
    const StreamSample s = test::sample_at(f, i, {"cur_strb"});
    cal.add(s, flag[static_cast<size_t>(i)]);
    if (flag[static_cast<size_t>(i)] && cal.rls_updates() > 0 && cal.samples() % 2000 == 0) {
      history.emplace_back(cal.samples(), evaluate_model(cal.rls(), f, "mag_1_c").std_nT);
    }
  }
  EXPECT_EQ(cal.segments(), 8);  // 4 box legs + 4 cloverleaf legs
  const Model batch = cal.batch();
  ASSERT_EQ(batch.coefficients.size(), cli.coefficients.size());
  for (Eigen::Index j = 0; j < batch.coefficients.size(); ++j) {
    EXPECT_NEAR(batch.coefficients[j], cli.coefficients[j],
                1e-9 * std::abs(cli.coefficients[j]) + 1e-9)
        << batch.column_names[static_cast<size_t>(j)];
  }
  const double batch_std = evaluate_model(batch, f, "mag_1_c").std_nT;
  const double rls_std = evaluate_model(cal.rls(), f, "mag_1_c").std_nT;
  for (const auto& [n, s] : history)
    std::printf("  after %5ld samples: RLS std %.3f nT\n", static_cast<long>(n), s);
  std::printf("  final RLS std %.3f nT, batch (= calibrate) %.3f nT, TL without the term %.3f nT\n",
              rls_std, batch_std, test::tl_std(f));
  ASSERT_GE(history.size(), 2u);
  EXPECT_LT(rls_std, history.front().second);  // it improves as maneuvers accumulate
  EXPECT_LT(rls_std, 3.0 * batch_std);         // and ends near the batch solution
  EXPECT_LT(rls_std, 0.2 * test::tl_std(f));   // far below TL without the missing term
}

TEST(ManeuverDetector, FindsTheCalibrationManeuversFromTheRatesAlone) {
  // The detector sees only the INS rates; the simulator knows which lines are the box and the
  // cloverleaf. Calibrating on what it finds does as well as calibrating on the known lines.
  const FlightData& f = test::scenario("wire_strobe").flight;
  const Model templ = strobe_template();
  ManeuverDetector det;
  InflightCalibrator cal(templ, 1.0);
  const auto known = f.select(templ.fit.lines, {});
  std::vector<bool> in_known(static_cast<size_t>(f.size()), false);
  for (auto i : known) in_known[static_cast<size_t>(i)] = true;
  long hits = 0, detected = 0;
  for (Eigen::Index i = 0; i < f.size(); ++i) {
    const bool m = det.update(f.tt()[i], f.column("pitch_rate")[i], f.column("roll_rate")[i],
                              f.column("yaw_rate")[i]);
    detected += m;
    hits += m && in_known[static_cast<size_t>(i)];
    cal.add(test::sample_at(f, i, {"cur_strb"}), m);
  }
  const double precision = static_cast<double>(hits) / detected;
  const double recall = static_cast<double>(hits) / static_cast<double>(known.size());
  const double auto_std = evaluate_model(cal.batch(), f, "mag_1_c").std_nT;
  const double lines_std = test::tl_std(f, {"current:cur_strb"});
  std::printf(
      "  detected %ld samples in %d segments: precision %.2f, recall %.2f; std %.3f nT "
      "(known lines: %.3f)\n",
      detected, cal.segments(), precision, recall, auto_std, lines_std);
  EXPECT_GT(precision, 0.85);  // measured 0.90: turn entries and leg ends are caught too
  EXPECT_GT(recall, 0.6);
  EXPECT_LT(auto_std, 1.3 * lines_std);
}

}  // namespace
}  // namespace magcomp
