// The figures a user judges a compensation by: the per-sample uncertainty (coverage on unseen
// lines, online = offline), the figure of merit against the simulator's truth, the improvement
// ratio.
#include <gtest/gtest.h>

#include "magcomp/core/evaluate/evaluation.h"
#include "magcomp/core/evaluate/figure_of_merit.h"
#include "magcomp/core/fit/model_fit.h"
#include "scenario_cache.h"

namespace magcomp {
namespace {

TEST(Uncertainty, TheVarianceCoversTheErrorsOnLinesTheFitNeverSaw) {
  // noise_only: the model is right and the error is the sensors' white noise.
  const FlightData& f = test::scenario("noise_only").flight;
  Model m = test::reference_tl(f);
  fit_model(m, {&f});
  const Evaluation ev = evaluate_model(m, f, "mag_1_c");
  const auto line = f.column("line");
  long n = 0, in1 = 0, in2 = 0;
  for (Eigen::Index i = 0; i < f.size(); ++i) {
    if (std::find(m.fit.lines.begin(), m.fit.lines.end(), line[i]) != m.fit.lines.end()) continue;
    const double e = ev.error_nT[i], v = ev.variance_nT2[i];
    if (!std::isfinite(e) || !std::isfinite(v)) continue;
    ++n;
    in1 += e * e <= v;
    in2 += e * e <= 4 * v;
  }
  const double c1 = static_cast<double>(in1) / n, c2 = static_cast<double>(in2) / n;
  std::printf("  %ld held-out samples: %.3f within 1 sigma, %.3f within 2 sigma (sigma %.3f nT)\n",
              n, c1, c2, std::sqrt(ev.variance_nT2[n / 2]));
  EXPECT_NEAR(c1, 0.68, 0.05);
  EXPECT_NEAR(c2, 0.95, 0.03);
  // The coefficients' part is there, and small beside the noise on this flight.
  EXPECT_GT(ev.variance_nT2.maxCoeff(), m.report.noise_variance_nT2);
}

TEST(Uncertainty, OnlineEqualsOfflineAndTheFileCarriesIt) {
  const FlightData& f = test::scenario("two_effects").flight;
  const Model fitted = test::calibrated_tl(f, {"current:cur_strb", "lag:0.3"});
  const std::string dir = test::temp_dir("variance");
  save_model_yaml(fitted, dir + "/m.yaml");
  const Model m = load_model_yaml(dir + "/m.yaml");
  ASSERT_EQ(m.report.coefficient_covariance.rows(), m.coefficients.size());
  EXPECT_DOUBLE_EQ(m.report.noise_variance_nT2, fitted.report.noise_variance_nT2);
  const Eigen::VectorXd offline = compensation_variance_nT2(m, f);
  StreamingCompensator sc(m);
  std::vector<StreamOutput> out;
  for (Eigen::Index i = 0; i < f.size(); ++i) {
    for (const auto& o : sc.push(test::sample_at(f, i, sc.required_channels()))) out.push_back(o);
  }
  for (const auto& o : sc.flush()) out.push_back(o);
  ASSERT_EQ(static_cast<Eigen::Index>(out.size()), f.size());
  double worst = 0;
  long finite = 0;
  for (Eigen::Index i = 0; i < f.size(); ++i) {
    const double a = out[static_cast<size_t>(i)].variance_nT2, b = offline[i];
    if (!std::isfinite(b)) continue;
    ++finite;
    worst = std::max(worst, std::abs(a - b) / b);
  }
  std::printf("  %ld samples: worst relative |online - offline| variance %.2e\n", finite, worst);
  EXPECT_GT(finite, f.size() - 10);
  EXPECT_LT(worst, 1e-9);
}

TEST(FigureOfMerit, TheUncompensatedFomMatchesTheTruthAndTheModelRemovesIt) {
  // The box of tl_only: 4 headings x pitch, roll, yaw. The simulator's truth holds the aircraft
  // field at magnetometer 5, so the uncompensated FOM is known.
  const sim::Simulation& s = test::scenario("tl_only");
  const FlightData& f = s.flight;
  const Model m = test::calibrated_tl(f);
  const Evaluation ev = evaluate_model(m, f, "mag_1_c");
  const FigureOfMerit& fom = ev.fom;
  const double truth = fom_on_windows(f, m.fit, fom, s.truth.column("mag_5_uc.aircraft"));
  std::printf("  %zu maneuvers; FOM uncompensated %.2f nT (truth %.2f nT), compensated %.3f nT\n",
              fom.signatures.size(), fom.uncompensated_fom_nT, truth, fom.fom_nT);
  for (const auto& sig : fom.signatures) {
    std::printf("    %-5s %s  %.3f nT (uncompensated %.2f nT)\n", sig.axis.c_str(),
                sig.heading.c_str(), sig.peak_to_peak_nT, sig.uncompensated_peak_to_peak_nT);
  }
  EXPECT_EQ(fom.signatures.size(), 12u);
  EXPECT_NEAR(fom.uncompensated_fom_nT, truth, 0.10 * truth);
  EXPECT_LT(fom.fom_nT, 0.05 * fom.uncompensated_fom_nT);
  // The improvement ratio is the ratio of the two stds, line by line and overall.
  EXPECT_NEAR(ev.improvement_ratio, ev.uncompensated_std_nT / ev.std_nT, 1e-12);
  for (const auto& l : ev.per_line) {
    if (l.n > 10) {
      EXPECT_NEAR(l.improvement_ratio, l.uncompensated_std_nT / l.std_nT, 1e-9);
    }
  }
  EXPECT_GT(ev.improvement_ratio, 10.0);
}

}  // namespace
}  // namespace magcomp

namespace magcomp {
namespace {

TEST(Uncertainty, TheHeldOutErrorEntersEachSamplesVariance) {
  // two_effects with plain TL: the wire and the lag are missing, so the error on the lines the
  // fit never saw is far above the fit's noise; it replaces the noise in every sample's variance,
  // and the model file carries it.
  const FlightData& f = test::scenario("two_effects").flight;
  Model tl = test::calibrated_tl(f);
  Model full = test::calibrated_tl(f, {"lag:0.3", "current:cur_strb"});
  const auto [tl_var, tl_rows] = holdout_error_variance_nT2(tl, {&f}, "mag_1_c");
  const auto [full_var, full_rows] = holdout_error_variance_nT2(full, {&f}, "mag_1_c");
  std::printf(
      "  held-out error std: TL %.3f nT, TL + wire + lag %.3f nT (%ld rows); fit noise "
      "%.3f and %.3f nT\n",
      std::sqrt(tl_var), std::sqrt(full_var), static_cast<long>(tl_rows),
      std::sqrt(tl.report.noise_variance_nT2), std::sqrt(full.report.noise_variance_nT2));
  ASSERT_GT(tl_rows, 10000);
  EXPECT_GT(tl_var, 10 * full_var);  // the missing effects show
  // Independent: the error's own line-demeaned variance on the rows not fitted.
  const Evaluation ev = evaluate_model(full, f, "mag_1_c");
  std::vector<bool> fitted(static_cast<size_t>(f.size()), false);
  for (Eigen::Index i : f.select(full.fit.lines, full.fit.windows))
    fitted[static_cast<size_t>(i)] = true;
  Eigen::VectorXd held = ev.error_nT;
  for (Eigen::Index i = 0; i < f.size(); ++i)
    if (fitted[static_cast<size_t>(i)]) held[i] = NAN;
  const double s = pooled_std(held, f.column("line"));
  EXPECT_NEAR(full_var, s * s, 1e-9 * s * s);
  const double before = compensation_variance_nT2(tl, f)[f.size() / 2];
  tl.report.holdout_error_variance_nT2 = tl_var;
  const double after = compensation_variance_nT2(tl, f)[f.size() / 2];
  EXPECT_NEAR(after - before, tl_var - tl.report.noise_variance_nT2, 1e-6 * tl_var);
  const std::string path = test::temp_dir("holdout") + "/tl.yaml";
  save_model_yaml(tl, path);
  EXPECT_DOUBLE_EQ(load_model_yaml(path).report.holdout_error_variance_nT2, tl_var);
}

}  // namespace
}  // namespace magcomp
