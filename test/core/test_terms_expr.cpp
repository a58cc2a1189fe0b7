// Terms of the language: shorthands, projections, free parameters estimated by the fit.
#include <gtest/gtest.h>

#include "magcomp/core/apply/apply.h"
#include "magcomp/core/error.h"
#include "magcomp/core/fit/model_fit.h"
#include "magcomp/core/fit/parameter_fit.h"
#include "magcomp/core/model/terms_expr.h"
#include "scenario_cache.h"

namespace magcomp {
namespace {

Eigen::MatrixXd columns(const std::string& spec, const FlightData& f) {
  const auto t = make_term(spec);
  const TermInputs in = make_term_inputs(f, "flux_c", 50000.0);
  Eigen::MatrixXd c(f.size(), t->columns());
  t->build(in, c);
  return c;
}

TEST(TermsExpr, ShorthandsKeepTheirNamesAndEqualTheirExpressions) {
  const FlightData& f = test::scenario("wire_strobe").flight;
  const auto cur = make_term("current:cur_strb");
  EXPECT_EQ(cur->spec(), "current:cur_strb");
  EXPECT_EQ(
      cur->column_names(),
      (std::vector<std::string>{"current:cur_strb.x", "current:cur_strb.y", "current:cur_strb.z"}));
  EXPECT_EQ(make_term("dcurrent:cur_strb")->spec(), "dcurrent:cur_strb");
  EXPECT_EQ(make_term("rate:pitch_rate")->column_names()[2], "rate:pitch_rate.z");
  EXPECT_EQ(columns("current:cur_strb", f), columns("field:cur_strb", f));
  EXPECT_EQ(columns("dcurrent:cur_strb", f), columns("field:cur_strb|d", f));
  // The columns themselves: B̂i · I, and B̂i · dI/dt (central difference per second).
  const TermInputs in = make_term_inputs(f, "flux_c", 50000.0);
  const Eigen::MatrixXd c = columns("current:cur_strb", f);
  const Eigen::MatrixXd dc = columns("dcurrent:cur_strb", f);
  const auto i = f.column("cur_strb");
  for (Eigen::Index k : {Eigen::Index(1), Eigen::Index(500), f.size() - 2}) {
    for (int a = 0; a < 3; ++a) {
      EXPECT_DOUBLE_EQ(c(k, a), in.direction(k, a) * i[k]);
      const double di = (i[k + 1] - i[k - 1]) / (f.tt()[k + 1] - f.tt()[k - 1]);
      EXPECT_NEAR(dc(k, a), in.direction(k, a) * di, 1e-9 * std::abs(di) + 1e-12);
    }
  }
}

TEST(TermsExpr, ProjectionsGiveTheirColumns) {
  const FlightData& f = test::scenario("wire_strobe").flight;
  const TermInputs in = make_term_inputs(f, "flux_c", 50000.0);
  EXPECT_EQ(make_term("field:B|decay(0.8)")->columns(), 9);
  EXPECT_EQ(make_term("field:B|decay(0.8)")->column_names()[1], "field:B|decay(0.8).xy");
  EXPECT_EQ(make_term("induced:cur_heat|lp(60)")->columns(), 6);
  EXPECT_EQ(make_term("scalar:vol_cabt|lp(600)")->column_names(),
            std::vector<std::string>{"scalar:vol_cabt|lp(600)"});
  EXPECT_EQ(make_term("scalar:B")->columns(), 3);
  // induced: B̂i B̂j |B| s / bt; scalar: s itself; a product multiplies sample by sample.
  const Eigen::MatrixXd ind = columns("induced:cur_heat", f);
  const Eigen::MatrixXd sc = columns("scalar:cur_heat*cur_strb", f);
  const Eigen::Index k = 1234;
  EXPECT_NEAR(
      ind(k, 1),
      in.direction(k, 0) * in.direction(k, 1) * in.total_nT[k] * f.column("cur_heat")[k] / 50000.0,
      1e-12);
  EXPECT_DOUBLE_EQ(sc(k, 0), f.column("cur_heat")[k] * f.column("cur_strb")[k]);
  EXPECT_THROW(make_term("induced:B"), Error);
  EXPECT_THROW(make_term("current:cur_strb|d"), Error);
  try {
    make_term("field:cur_strb|lp(-1)");
    FAIL();
  } catch (const Error& e) {
    EXPECT_NE(std::string(e.what()).find("term 'field:cur_strb|lp(-1)'"), std::string::npos);
  }
}

TEST(TermsExpr, FreeParametersAreEstimatedByTheFitAndWrittenBack) {
  const FlightData& f = test::scenario("thermal_heater").flight;
  Model m = test::reference_tl(f);
  m.add_term("field:cur_heat|pow(2)|lp(?)");
  fit_model(m, {&f});
  const std::string term = m.terms.back();
  const auto e = parse_expr_term(term);
  ASSERT_TRUE(e);
  ASSERT_FALSE(e->signal().has_free()) << term;
  const double tau = e->signal().transforms.back().param;
  std::printf("  estimated %s (truth: time constant 150 s); %s\n", term.c_str(),
              m.report.estimates.at(0).c_str());
  EXPECT_NEAR(tau, 150.0, 15.0);
  // The numbers are in the file, and the file reads back to the same model.
  const std::string dir = test::temp_dir("expr");
  save_model_yaml(m, dir + "/m.yaml");
  const Model back = load_model_yaml(dir + "/m.yaml");
  EXPECT_EQ(back.terms, m.terms);
  EXPECT_EQ(back.column_names, m.column_names);
  EXPECT_LT((back.coefficients - m.coefficients).cwiseAbs().maxCoeff(), 1e-12);
  // Adding the same expression with a new value replaces it (one lag, one heater response).
  Model r = back;
  EXPECT_TRUE(r.add_term("field:cur_heat|pow(2)|lp(80)"));
  EXPECT_EQ(r.terms.back(), "field:cur_heat|pow(2)|lp(80)");
  EXPECT_EQ(r.terms.size(), back.terms.size());
  EXPECT_TRUE(r.add_term("field:cur_heat|lp(80)"));  // another shape: added
  EXPECT_EQ(r.terms.size(), back.terms.size() + 1);
}

TEST(TermsExpr, AThresholdIsWrittenWithTheDigitsThatKeepEverySampleOnItsSide) {
  // A relay's control current dwelling near its 0.30743 A threshold: samples every 0.1 mA from
  // 0.3 A to 0.32 A. The objective counts the samples on the wrong side of the true threshold.
  const double truth_A = 0.30743;
  const auto wrong_side = [&](const std::vector<double>& values) {
    return [&values, truth_A](double threshold_A) {
      double n = 0;
      for (double v : values) n += (v > threshold_A) != (v > truth_A);
      return n;
    };
  };
  std::vector<double> dense;
  for (int k = 0; k <= 200; ++k) dense.push_back(0.3 + 1e-4 * k);
  double best = NAN;
  const double found_A = scan_threshold(dense, wrong_side(dense), &best);
  EXPECT_EQ(best, 0.0) << found_A;
  EXPECT_EQ(wrong_side(dense)(found_A), 0.0) << found_A;
  // Three significant digits would put 0.3071..0.3074 A on the wrong side.
  EXPECT_EQ(wrong_side(dense)(0.307), 4.0);
  EXPECT_GT(found_A, 0.3074);
  EXPECT_LE(found_A, 0.3075);
  // Where the samples are sparse near it, three digits keep every one on its side.
  std::vector<double> sparse;
  for (int k = 0; k <= 20; ++k) sparse.push_back(0.2 + 1e-2 * k);
  const double written_A = scan_threshold(sparse, wrong_side(sparse), &best);
  EXPECT_EQ(best, 0.0);
  char three[32];
  std::snprintf(three, sizeof(three), "%.3g", written_A);
  EXPECT_EQ(std::strtod(three, nullptr), written_A) << written_A;
}

TEST(TermsExpr, TheStreamingCompensatorRunsEveryTransformAsTheBatchDoes) {
  const FlightData& f = test::scenario("wire_thermal_lag").flight;
  Model m = test::reference_tl(f);
  for (const char* t :
       {"lag:0.2", "current:cur_strb", "field:cur_heat|pow(2)|lp(150)", "field:B|decay(0.8)",
        "scalar:vol_cabt|hp(300)", "field:cur_tank|int|hp(600)", "field:cur_flap|delay(0.7)",
        "induced:cur_ac_hi|lp(20)", "field:nrml_acc*cur_com_1|abs", "scalar:mag_5_uc|d",
        "field:cur_acpwr|ramp(16)|lp(40)", "field:cur_acpwr|ramp(20)|lp(40)"}) {
    m.add_term(t);
  }
  fit_model(m, {&f});
  const Eigen::VectorXd batch = compensate(m, f);
  StreamingCompensator sc(m);
  std::vector<StreamOutput> out;
  for (Eigen::Index i = 0; i < f.size(); ++i) {
    for (const auto& o : sc.push(test::sample_at(f, i, sc.required_channels()))) out.push_back(o);
  }
  const int lookahead = sc.lookahead();
  for (const auto& o : sc.flush()) out.push_back(o);
  ASSERT_EQ(static_cast<Eigen::Index>(out.size()), f.size());
  double worst = 0;
  long nan = 0;
  for (Eigen::Index i = 0; i < f.size(); ++i) {
    const double a = out[static_cast<size_t>(i)].compensated_nT, b = batch[i];
    if (std::isnan(b)) {
      EXPECT_TRUE(std::isnan(a)) << i;
      ++nan;
      continue;
    }
    worst = std::max(worst, std::abs(a - b));
  }
  std::printf(
      "  %zu terms, lookahead %d samples: worst |stream - batch| = %.2e nT (%ld NaN at "
      "the edges in both)\n",
      m.terms.size(), lookahead, worst, nan);
  EXPECT_LT(worst, 1e-6);
  EXPECT_LT(nan, 10);
}

}  // namespace
}  // namespace magcomp
