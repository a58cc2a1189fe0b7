// Model: closed-form recovery of known coefficients, YAML round trip, bad input.
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <fstream>
#include <nlohmann/json.hpp>
#include <set>

#include "magcomp/core/error.h"
#include "magcomp/core/evaluate/evaluation.h"
#include "magcomp/core/fit/model_fit.h"
#include "magcomp/core/model/model.h"
#include "scenario_cache.h"
#include "synthetic_flight.h"
#include "test_util.h"

namespace magcomp {
namespace {

Model tl16() { return test::tl16_model(); }

Eigen::VectorXd true_coefficients(Eigen::Index p) { return test::known_coefficients(p); }

// `x` through a first-order lag of tau_s (dt_s the sample period), by its exact discrete
// recursion, started at x's first value.
Eigen::VectorXd first_order_lag(const Eigen::VectorXd& x, double dt_s, double tau_s) {
  const double a = 1.0 - std::exp(-dt_s / tau_s);
  Eigen::VectorXd y(x.size());
  if (x.size() == 0) return y;
  y[0] = x[0];
  for (Eigen::Index i = 1; i < x.size(); ++i) y[i] = y[i - 1] + a * (x[i] - y[i - 1]);
  return y;
}

// The lines of `d` with no sample in the calibration selection of `fit`, ascending.
std::vector<double> survey_lines(const FlightData& d, const FitSettings& fit) {
  const std::vector<Eigen::Index> in_cal = d.select(fit.lines, fit.windows);
  std::set<double> survey;
  const Eigen::VectorXd line = d.column("line");
  for (Eigen::Index i = 0; i < line.size(); ++i)
    if (!std::binary_search(in_cal.begin(), in_cal.end(), i)) survey.insert(line[i]);
  return std::vector<double>(survey.begin(), survey.end());
}

// The random-effects base flight with gain_nT per unit of the flap motor's current through a
// tau_s first-order lag added to its scalar (a drift, nT).
FlightData flight_with_flap_drift(double gain_nT, double tau_s) {
  FlightData d = test::scenario("random_base").flight;
  d.mutable_column("mag_5_uc") += gain_nT * first_order_lag(d.column("cur_flap"), d.dt_s(), tau_s);
  return d;
}

TEST(Model, BandpassFitRecoversKnownCoefficients) {
  Model m = tl16();
  const Eigen::VectorXd c_true = true_coefficients(16);
  const FlightData d = test::synthetic_tl_flight(m, c_true);
  fit_model(m, {&d});
  ASSERT_EQ(m.coefficients.size(), 16);
  EXPECT_EQ(m.report.segments, 2);
  for (Eigen::Index j = 0; j < 16; ++j) {
    EXPECT_NEAR(m.coefficients[j], c_true[j], 1e-3 * std::abs(c_true[j]) + 1e-3)
        << m.column_names[j];
  }
  // Evaluated on the lines the fit never saw, the error is only the (unobservable) mean.
  const Evaluation ev = evaluate_model(m, d, "mag_1_c");
  EXPECT_LT(ev.std_nT, 1e-3);
  EXPECT_EQ(ev.per_line.size(), 4u);
}

TEST(Model, ALineTheFlightsDoNotFlyIsWarnedAboutByItsKey) {
  // A mistyped line number in fit.lines or fit.slow_lines leaves the fit on fewer rows than the
  // model file lists: each such line is a warning naming its key, the line and the flight; the
  // lines flown give none, and the fit is that of the lines flown.
  Model m = tl16();
  const Eigen::VectorXd c_true = true_coefficients(16);
  const FlightData d = test::synthetic_tl_flight(m, c_true);
  Model typo = m;
  typo.fit.lines.push_back(1001.2);  // for 1001.02, say
  typo.fit.slow_lines = {1001.01, 5555.0};
  fit_model(m, {&d});
  fit_model(typo, {&d});
  const auto count = [](const Model& x, const std::string& text) {
    return std::count_if(x.report.warnings.begin(), x.report.warnings.end(),
                         [&](const std::string& w) { return w.find(text) != w.npos; });
  };
  for (const std::string& w : typo.report.warnings) std::printf("  warning: %s\n", w.c_str());
  EXPECT_EQ(count(m, "is flown on none of"), 0);
  EXPECT_EQ(count(typo, "is flown on none of"), 2);
  EXPECT_EQ(count(typo, "fit.lines: line 1001.2 is flown on none of " + d.source()), 1);
  EXPECT_EQ(count(typo, "fit.slow_lines: line 5555 is flown on none of " + d.source()), 1);
  ASSERT_EQ(typo.coefficients.size(), m.coefficients.size());
  EXPECT_LT((typo.coefficients - m.coefficients).norm(), 1e-9 * m.coefficients.norm());
}

TEST(Model, ReferenceFitRecoversBias) {
  Model m = tl16();
  m.terms.push_back("bias");
  m.fit.method = FitMethod::kReference;
  m.fit.reference = "mag_1_c";
  m.fit.lines.clear();
  Eigen::VectorXd c_true = true_coefficients(17);
  c_true[16] = 0.0;
  const FlightData d = test::synthetic_tl_flight(m, c_true, 6000, 123.4);
  fit_model(m, {&d});
  EXPECT_NEAR(m.coefficients[16], 123.4, 1e-3);
  EXPECT_NEAR(m.coefficients[0], c_true[0], 1e-3 * std::abs(c_true[0]));
}

TEST(Model, YamlRoundTripKeepsEveryDigit) {
  Model m = tl16();
  m.add_term("current:cur_strb");
  const FlightData d = [&] {
    Model plain = tl16();
    FlightData f = test::synthetic_tl_flight(plain, true_coefficients(16));
    Eigen::VectorXd cur(f.size());
    for (Eigen::Index i = 0; i < f.size(); ++i) cur[i] = ((i / 7) % 2) * 1.5;
    f.set("cur_strb", cur);
    return f;
  }();
  fit_model(m, {&d});
  const std::string path = test::temp_dir("model") + "/fitted.yaml";
  save_model_yaml(m, path);
  const Model r = load_model_yaml(path);
  EXPECT_EQ(r.terms, m.terms);
  ASSERT_EQ(r.coefficients.size(), m.coefficients.size());
  for (Eigen::Index j = 0; j < r.coefficients.size(); ++j) {
    EXPECT_EQ(r.coefficients[j], m.coefficients[j]);
  }
  EXPECT_EQ(r.fit.lines, m.fit.lines);
}

TEST(Model, ALearnedLawIsMarkedAsABlackBoxInTheFile) {
  Model m = tl16();
  const size_t before = m.terms.size();
  // Hinges of one channel at other knots are other pieces of the law, not one term re-valued.
  for (const char* t : {"field:cur_strb|ramp(0)|lp(20)", "field:cur_strb|ramp(0.5)|lp(20)"}) {
    ASSERT_TRUE(m.add_term(t));
    m.black_box_terms.push_back(t);
  }
  ASSERT_EQ(m.terms.size(), before + 2);
  const std::string dir = test::temp_dir("model");
  save_model_yaml(m, dir + "/learned.yaml");
  const Model r = load_model_yaml(dir + "/learned.yaml");
  EXPECT_EQ(r.terms, m.terms);
  EXPECT_EQ(r.black_box_terms, m.black_box_terms);
  std::ofstream(dir + "/bad.yaml")
      << "scalar: a\nvector: b\nterms: [permanent]\nblack_box_terms: [current:cur_strb]\n";
  try {
    load_model_yaml(dir + "/bad.yaml");
    ADD_FAILURE() << "a black-box term outside the model's terms was read";
  } catch (const Error& e) {
    EXPECT_NE(std::string(e.what()).find("black_box_terms"), std::string::npos) << e.what();
  }
}

TEST(Model, AFileWithTwoLagsIsRefusedNotReadAsOne) {
  // A model has one lag of its scalar: a second added in code replaces the first
  // (Model::add_term), so a file listing two would be read as a model other than the one whose
  // coefficients it holds (0.35 + 0.27 s of lag applied where they were fitted, 0.27 s read).
  Model m;
  ASSERT_TRUE(m.add_term("lag:0.35"));
  ASSERT_TRUE(m.add_term("lag:0.27"));
  ASSERT_EQ(std::count_if(m.terms.begin(), m.terms.end(),
                          [](const TermSpec& t) { return t.text().rfind("lag:", 0) == 0; }),
            1);
  EXPECT_DOUBLE_EQ(m.scalar_lag_s(), 0.27);
  const std::string dir = test::temp_dir("model");
  std::ofstream(dir + "/one_lag.yaml")
      << "scalar: a\nvector: b\nterms: [permanent, lag:0.27, current:cur_strb]\n";
  EXPECT_DOUBLE_EQ(load_model_yaml(dir + "/one_lag.yaml").scalar_lag_s(), 0.27);
  std::ofstream(dir + "/two_lags.yaml")
      << "scalar: a\nvector: b\nterms: [permanent, lag:0.35, current:cur_strb, lag:0.27]\n";
  try {
    load_model_yaml(dir + "/two_lags.yaml");
    ADD_FAILURE() << "a file with two lags was read";
  } catch (const Error& e) {
    const std::string what = e.what();
    EXPECT_NE(what.find("two_lags.yaml"), std::string::npos) << what;
    EXPECT_NE(what.find("key 'terms'"), std::string::npos) << what;
    EXPECT_NE(what.find("lag:0.35, lag:0.27"), std::string::npos) << what;
  }
}

TEST(Model, ASlowTermIsFittedAfterTheBandPassAgainstTheReference) {
  // A heater: 2 nT per A of the fuel pump's current through a 150 s first-order lag (computed
  // here by its exact discrete recursion), added to the scalar of a flight without hidden
  // effects. Its band-pass content on the 8 min of calibration maneuvers is a fraction of a
  // percent: the band-pass stage cannot size it, the slow stage (against mag_1_c, unfiltered,
  // segment means and the TL columns' span removed) does.
  FlightData d = test::scenario("random_base").flight;
  const double gain_nT_per_A = 2.0, tau_s = 150.0;
  d.mutable_column("mag_5_uc") +=
      gain_nT_per_A * first_order_lag(d.column("cur_tank"), d.dt_s(), tau_s);
  const std::string term = "scalar:cur_tank|lp(150)";
  Model band = load_model_yaml(test::source_dir() + "/config/models/tl_sim.yaml");
  band.add_term(term);
  Model slow = band;
  slow.slow_terms = {term};
  slow.fit.reference = "mag_1_c";
  fit_model(band, {&d});
  fit_model(slow, {&d});
  const Eigen::Index c = band.coefficients.size() - 1;
  ASSERT_NE(slow.column_names[static_cast<size_t>(c)].find("cur_tank"), std::string::npos);
  const double band_err = evaluate_model(band, d, "mag_1_c").std_nT;
  const double slow_err = evaluate_model(slow, d, "mag_1_c").std_nT;
  std::printf("  gain %.3f nT/A by the slow stage, %.3f by the band-pass; error %.3f vs %.3f nT\n",
              slow.coefficients[c], band.coefficients[c], slow_err, band_err);
  EXPECT_NEAR(slow.coefficients[c], gain_nT_per_A, 0.05 * gain_nT_per_A);
  EXPECT_GT(std::abs(band.coefficients[c] - gain_nT_per_A), 0.2 * gain_nT_per_A);
  EXPECT_LT(slow_err, 0.5 * band_err);
  // The TL coefficients are the band-pass stage's, less what it took of the heater's band
  // content (given back once the heater is sized): nearer those of TL on the flight without the
  // heater than TL's on the flight with it.
  Model tl = load_model_yaml(test::source_dir() + "/config/models/tl_sim.yaml");
  Model tl_clean = tl;
  fit_model(tl, {&d});
  const FlightData clean = test::scenario("random_base").flight;
  fit_model(tl_clean, {&clean});
  ASSERT_EQ(tl.coefficients.size(), c);
  const double off_slow = (slow.coefficients.head(c) - tl_clean.coefficients).norm();
  const double off_tl = (tl.coefficients - tl_clean.coefficients).norm();
  std::printf(
      "  TL's coefficients from those on the flight without the heater: %.4f, TL's on the "
      "flight with it %.4f\n",
      off_slow, off_tl);
  EXPECT_LT(off_slow, 0.5 * off_tl);
  EXPECT_LT((slow.coefficients.head(c) - tl.coefficients).norm(), 1e-3 * tl.coefficients.norm());
  for (const auto& w : slow.report.warnings)
    EXPECT_EQ(w.find("cur_tank"), std::string::npos) << w;  // not "set to 0": it is fitted
  // In the file: the list, and the errors that name it.
  const std::string dir = test::temp_dir("model");
  save_model_yaml(slow, dir + "/slow.yaml");
  const Model r = load_model_yaml(dir + "/slow.yaml");
  EXPECT_EQ(r.slow_terms, slow.slow_terms);
  EXPECT_EQ(r.fit.reference, "mag_1_c");
  for (const char* bad :
       {"terms: [permanent]\nslow_terms: [current:cur_strb]\nfit: {reference: mag_1_c}\n",
        "terms: [permanent, 'scalar:cur_strb|lp(20)']\nslow_terms: ['scalar:cur_strb|lp(20)']\n",
        "terms: [permanent, 'scalar:cur_strb|lp(?)']\nslow_terms: ['scalar:cur_strb|lp(?)']\n"
        "fit: {reference: mag_1_c}\n"}) {
    std::ofstream(dir + "/bad.yaml") << "scalar: a\nvector: b\n" << bad;
    try {
      load_model_yaml(dir + "/bad.yaml");
      ADD_FAILURE() << "read: " << bad;
    } catch (const Error& e) {
      EXPECT_NE(std::string(e.what()).find("slow_terms"), std::string::npos) << e.what();
    }
  }
}

TEST(Model, ASlowTermIsSizedOnTheSlowLinesWhereItsChannelMoves) {
  // A drift: 1.5 nT per unit of the flap motor's current through a 400 s first-order lag (its
  // exact discrete recursion), added to the scalar of a flight without hidden effects. Through
  // 400 s the drift barely moves within a calibration segment, so that the slow stage sizes it
  // from little; on the survey lines (fit.slow_lines, each line's mean removed) it moves by its
  // whole span. Sized there, the gain is found within 5 %.
  const double gain_nT = 1.5;
  const FlightData d = flight_with_flap_drift(gain_nT, 400.0);
  Model cal = load_model_yaml(test::source_dir() + "/config/models/tl_sim.yaml");
  cal.add_slow_term(TermSpec("scalar:cur_flap|lp(400)"), "mag_1_c");
  Model lines = cal;
  lines.fit.slow_lines = survey_lines(d, cal.fit);
  ASSERT_GE(lines.fit.slow_lines.size(), 2u);
  fit_model(cal, {&d});
  fit_model(lines, {&d});
  const Eigen::Index c = cal.coefficients.size() - 1;
  const double cal_err = evaluate_model(cal, d, "mag_1_c").std_nT;
  const double lines_err = evaluate_model(lines, d, "mag_1_c").std_nT;
  std::printf(
      "  gain %.3f nT on the slow lines, %.3f on the calibration rows alone; error %.3f "
      "vs %.3f nT\n",
      lines.coefficients[c], cal.coefficients[c], lines_err, cal_err);
  EXPECT_NEAR(lines.coefficients[c], gain_nT, 0.05 * gain_nT);
  EXPECT_GT(std::abs(cal.coefficients[c] - gain_nT), 0.2 * gain_nT);
  EXPECT_LE(lines_err, cal_err + 1e-3);
  // The report says where it was sized; the band-pass stage is the same.
  bool said = false;
  for (const auto& e : lines.report.estimates) said = said || e.find("fit.slow_lines") != e.npos;
  EXPECT_TRUE(said);
  // (less what the band-pass took of the drift's band content, a part in 10^4 of them)
  EXPECT_LT((lines.coefficients.head(c) - cal.coefficients.head(c)).norm(),
            1e-3 * cal.coefficients.head(c).norm());
  // In the file, and a bad entry named.
  const std::string dir = test::temp_dir("model");
  save_model_yaml(lines, dir + "/lines.yaml");
  EXPECT_EQ(load_model_yaml(dir + "/lines.yaml").fit.slow_lines, lines.fit.slow_lines);
  std::ofstream(dir + "/bad.yaml") << "scalar: a\nvector: b\nterms: [permanent]\n"
                                      "fit: {reference: mag_1_c, slow_lines: [1, .nan]}\n";
  try {
    load_model_yaml(dir + "/bad.yaml");
    ADD_FAILURE() << "read a NaN line";
  } catch (const Error& e) {
    EXPECT_NE(std::string(e.what()).find("fit.slow_lines"), std::string::npos) << e.what();
  }
}

TEST(Model, AReferenceFitSizesASlowTermOnTheSlowLinesToo) {
  // The drift above under a fit against the stinger (fit.method reference, with a bias). As an
  // ordinary column the drift is sized on the calibration rows, where through 400 s it barely
  // moves and lies nearly within the bias's span. As a slow term with fit.slow_lines, the other
  // columns are fitted on the calibration rows and the drift after them, there and where it
  // moves (each segment's and line's mean removed), with the other columns' share given back:
  // its gain is found within 5 %. Without fit.slow_lines (the calibration rows alone, in two
  // stages) it is as loosely sized as jointly.
  const double gain_nT = 1.5;
  const FlightData d = flight_with_flap_drift(gain_nT, 400.0);
  Model joint = load_model_yaml(test::source_dir() + "/config/models/tl_sim.yaml");
  joint.fit.method = FitMethod::kReference;
  joint.fit.reference = "mag_1_c";
  joint.add_term(TermSpec("bias"));
  Model lines = joint;
  joint.add_term(TermSpec("scalar:cur_flap|lp(400)"));
  lines.add_slow_term(TermSpec("scalar:cur_flap|lp(400)"), "mag_1_c");
  Model staged = lines;
  lines.fit.slow_lines = survey_lines(d, lines.fit);
  ASSERT_GE(lines.fit.slow_lines.size(), 2u);
  fit_model(joint, {&d});
  fit_model(lines, {&d});
  fit_model(staged, {&d});
  const Eigen::Index c = joint.coefficients.size() - 1;
  ASSERT_EQ(lines.coefficients.size(), c + 1);
  const double joint_err = evaluate_model(joint, d, "mag_1_c").std_nT;
  const double lines_err = evaluate_model(lines, d, "mag_1_c").std_nT;
  const double staged_err = evaluate_model(staged, d, "mag_1_c").std_nT;
  std::printf(
      "  gain %.3f nT on the slow lines, %.3f fitted jointly on the calibration rows, %.3f in "
      "two stages there; error %.4f vs %.4f vs %.4f nT\n",
      lines.coefficients[c], joint.coefficients[c], staged.coefficients[c], lines_err, joint_err,
      staged_err);
  EXPECT_NEAR(lines.coefficients[c], gain_nT, 0.05 * gain_nT);
  EXPECT_GT(std::abs(joint.coefficients[c] - gain_nT), 0.2 * gain_nT);
  EXPECT_GT(std::abs(staged.coefficients[c] - gain_nT), 0.2 * gain_nT);
  EXPECT_LT(lines_err, joint_err - 0.02);
  EXPECT_LT(lines_err, staged_err);
  bool said = false;
  for (const auto& e : lines.report.estimates) said = said || e.find("fit.slow_lines") != e.npos;
  EXPECT_TRUE(said);
}

TEST(Model, ASlowFieldOfAChannelIsNotCountedTwiceByTheBandPassTerms) {
  // A heater's field, body-fixed: (g_x, g_y, g_z) nT per volt of the servo bus through a 200 s
  // first-order lag, projected on the field direction, added to the scalar of a flight without
  // hidden effects. The bus sits near its steady level: most of the term's columns are that level
  // times the direction cosines, which the permanent terms read too, so that the band-pass stage
  // takes that part as permanent field. The slow stage fits the columns beyond the band-pass
  // columns' span; the model gives back what the band-pass coefficients took of the columns, or
  // it carries the level times the gain twice, as a false permanent field. (Only their sum is
  // determined: the gain and the permanent field along it trade one for the other.)
  FlightData d = test::scenario("random_base").flight;
  const double tau_s = 200.0;
  const Eigen::Vector3d gain_nT_per_V(0.8, -0.5, 0.3);
  const Eigen::VectorXd bus = d.column("vol_srvo");
  const Eigen::VectorXd lagged = first_order_lag(bus, d.dt_s(), tau_s);
  const Eigen::VectorXd bx = d.column("flux_c_x"), by = d.column("flux_c_y"),
                        bz = d.column("flux_c_z");
  Eigen::VectorXd added(d.size());
  for (Eigen::Index i = 0; i < d.size(); ++i) {
    const Eigen::Vector3d b(bx[i], by[i], bz[i]);
    added[i] = lagged[i] * gain_nT_per_V.dot(b / b.norm());
  }
  const FlightData clean = d;
  d.mutable_column("mag_5_uc") += added;
  Model tl = load_model_yaml(test::source_dir() + "/config/models/tl_sim.yaml");
  Model m = tl;
  m.add_slow_term(TermSpec("field:vol_srvo|lp(200)"), "mag_1_c");
  m.fit.slow_lines = survey_lines(d, m.fit);
  fit_model(m, {&d});
  fit_model(tl, {&clean});
  const Eigen::Index p = tl.coefficients.size();
  ASSERT_EQ(m.coefficients.size(), p + 3);
  double mean = 0;
  for (Eigen::Index i = 0; i < bus.size(); ++i) mean += bus[i] / static_cast<double>(bus.size());
  const double err = evaluate_model(m, d, "mag_1_c").std_nT;
  const double clean_err = evaluate_model(tl, clean, "mag_1_c").std_nT;
  // The same model with the band-pass coefficients as the band-pass stage left them.
  Model kept = m;
  Model tl_added = load_model_yaml(test::source_dir() + "/config/models/tl_sim.yaml");
  fit_model(tl_added, {&d});
  kept.coefficients.head(p) = tl_added.coefficients;
  const double kept_err = evaluate_model(kept, d, "mag_1_c").std_nT;
  std::printf(
      "  bus level %.2f V; gain (%.3f, %.3f, %.3f) nT/V; error %.3f nT (TL on the clean flight "
      "%.3f), %.3f nT with the level left out of the band-pass terms\n",
      mean, m.coefficients[p], m.coefficients[p + 1], m.coefficients[p + 2], err, clean_err,
      kept_err);
  ASSERT_GT(std::abs(mean), 5.0);  // a bus with a level
  // The bus barely moves about its level, so that the gain's direction is loosely sized; what
  // the model predicts is right to the clean flight's error, and wrong by nanotesla without the
  // level given back.
  EXPECT_LT(err, clean_err + 0.05);
  EXPECT_GT(kept_err, 2.0 * err + 0.3);
}

TEST(Model, BadModelsNameTheKey) {
  const std::string dir = test::temp_dir("model");
  auto write = [&](const std::string& text) {
    std::ofstream(dir + "/m.yaml") << text;
    return dir + "/m.yaml";
  };
  auto message = [](const std::string& path) -> std::string {
    try {
      load_model_yaml(path);
    } catch (const Error& e) {
      return e.what();
    }
    return "";
  };
  EXPECT_NE(message(write("vector: flux_c\n")).find("'scalar'"), std::string::npos);
  EXPECT_NE(message(write("scalar: a\nvector: b\nterms: [permanent, warp]\n")).find("warp"),
            std::string::npos);
  EXPECT_NE(message(write("scalar: a\nvector: b\nfit: {method: magic}\n")).find("fit.method"),
            std::string::npos);
  EXPECT_NE(message(write("scalar: a\nvector: b\nfit: {lambda: -1}\n")).find("fit.lambda"),
            std::string::npos);
  EXPECT_NE(message(write("scalar: a\nvector: b\nfit: {band_hz: [0.9, 0.1]}\n")).find("band_hz"),
            std::string::npos);
  EXPECT_NE(message(dir + "/none.yaml").find("none.yaml"), std::string::npos);
  EXPECT_NE(message(write("scalar: a\nvector: b\nscalar: c\n")).find("'scalar' given twice"),
            std::string::npos);
  Model m = tl16();
  EXPECT_THROW(m.add_term("current:"), Error);
  EXPECT_FALSE(m.add_term("permanent"));
}

}  // namespace
}  // namespace magcomp
