// In-flight calibration: the batch solution equals `calibrate`; the recursive one converges to it.
#include <gtest/gtest.h>

#include "magcomp/core/inflight_calibrator.h"
#include "scenario_cache.h"

namespace magcomp {
namespace {

TEST(InflightCalibrator, BatchEqualsCalibrateAndRlsConvergesTowardIt) {
  const FlightData& f = test::scenario("wire_strobe").flight;
  Model templ = load_model_yaml(test::source_dir() + "/config/models/tl_sim.yaml");
  templ.add_term("current:cur_strb");
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

}  // namespace
}  // namespace magcomp
