// term_support: how often an added term's channel switched where it was fitted, its size and
// the uncertainty of that size, on a closed-form flight.
#include <gtest/gtest.h>

#include <cmath>
#include <functional>
#include <random>

#include "magcomp/core/diagnose/term_support.h"
#include "magcomp/core/fit/model_fit.h"
#include "magcomp/core/fit/parameter_fit.h"
#include "synthetic_flight.h"

namespace magcomp {
namespace {

// The 16-term TL model fitted against mag_1_c on every row (unfitted).
Model reference_tl16() {
  Model m = test::tl16_model();
  m.fit.method = FitMethod::kReference;
  m.fit.reference = "mag_1_c";
  m.fit.lines.clear();
  return m;
}

// A first-order noise of std sigma_nT, correlated by rho from one sample to the next.
Eigen::VectorXd correlated_noise(Eigen::Index n, double sigma_nT, double rho,
                                 std::mt19937_64* rng) {
  std::normal_distribution<double> normal(0.0, 1.0);
  Eigen::VectorXd noise(n);
  double v = sigma_nT * normal(*rng);
  for (Eigen::Index i = 0; i < n; ++i) {
    v = rho * v + sigma_nT * std::sqrt(1 - rho * rho) * normal(*rng);
    noise[i] = v;
  }
  return noise;
}

// The closed-form flight with a current `x` of 3 nT/A and a known noise on the scalar; the TL
// model and the model with the current's term, both fitted against the reference on every row.
struct Case {
  FlightData flight;
  Model start, with_term;
};

Case make_case(const std::function<double(int)>& current_A, double noise_nT) {
  Case c;
  c.start = reference_tl16();
  c.flight = test::synthetic_tl_flight(c.start, test::known_coefficients(16));
  Eigen::VectorXd x(c.flight.size()), noise(c.flight.size());
  for (Eigen::Index i = 0; i < x.size(); ++i) {
    x[i] = current_A(static_cast<int>(i));
    // A deterministic, white-looking sequence of std noise_nT (uniform on +-sqrt(3) sigma).
    noise[i] = noise_nT * std::sqrt(3.0) * std::fmod(std::sin(12.9898 * i) * 43758.5453, 1.0);
  }
  c.flight.set("cur_x", x);
  c.flight.mutable_column("mag_5_uc") += 3.0 * x + noise;
  fit_model(c.start, {&c.flight});
  c.with_term = c.start;
  c.with_term.add_term("scalar:cur_x");
  c.with_term.coefficients.resize(0);
  fit_model(c.with_term, {&c.flight});
  return c;
}

TEST(TermSupport, ATermWhoseChannelSwitchedTwiceIsSaidToBeUncertain) {
  // On for 500 samples of 6000: one switch on, one off.
  const Case c = make_case([](int i) { return i >= 1000 && i < 1500 ? 2.0 : 0.0; }, 0.1);
  const std::vector<TermSupport> s = term_support(c.with_term, c.start, c.flight);
  ASSERT_EQ(s.size(), 1u);
  EXPECT_EQ(s[0].term, "scalar:cur_x");
  EXPECT_EQ(s[0].channel, "cur_x");
  EXPECT_EQ(s[0].switches, 2);
  // The size: 3 nT/A times the current's std beyond what TL's columns take of it (a single pulse
  // follows the maneuvers' columns in part), at most 3 nT/A times the current's own std, 2 A *
  // sqrt(p (1 - p)) with p = 1/12.
  {
    const Eigen::MatrixXd tl = design_matrix(c.start, c.flight);
    Eigen::MatrixXd others(tl.rows(), tl.cols() + 1);
    others << tl, Eigen::VectorXd::Ones(tl.rows());
    const Eigen::VectorXd x = c.flight.column("cur_x");
    const Eigen::VectorXd beyond = x - others * others.colPivHouseholderQr().solve(x);
    const double expected = 3.0 * std::sqrt(beyond.squaredNorm() / static_cast<double>(x.size()));
    std::printf("  size %.4f nT: beyond TL's columns %.4f nT, the current's own std %.4f nT\n",
                s[0].size_nT, expected, 3.0 * 2.0 * std::sqrt(1.0 / 12 * 11.0 / 12));
    EXPECT_NEAR(s[0].size_nT, expected, 0.01);
    EXPECT_LE(s[0].size_nT, 3.0 * 2.0 * std::sqrt(1.0 / 12 * 11.0 / 12) + 0.01);
  }
  // Its uncertainty: the coefficient's sigma (about 0.1 nT / sqrt(500 * 4 A^2 * 11/12)) times the
  // current's rms; small against the noise, far from zero.
  ASSERT_TRUE(std::isfinite(s[0].size_sigma_nT));
  EXPECT_GT(s[0].size_sigma_nT, 0.0005);
  EXPECT_LT(s[0].size_sigma_nT, 0.02);
  const std::string note = support_note(s[0]);
  EXPECT_NE(note.find("cur_x switched 2 times"), std::string::npos) << note;
}

TEST(TermSupport, ATermWhoseChannelSwitchesOftenNeedsNoNote) {
  // A square wave of period 300 samples: 40 switches over the flight.
  const Case c = make_case([](int i) { return (i / 150) % 2 ? 2.0 : 0.0; }, 0.1);
  const std::vector<TermSupport> s = term_support(c.with_term, c.start, c.flight);
  ASSERT_EQ(s.size(), 1u);
  EXPECT_EQ(s[0].switches, 39);
  EXPECT_EQ(support_note(s[0]), "");
  // Nothing added: nothing to say.
  EXPECT_TRUE(term_support(c.start, c.start, c.flight).empty());
}

TEST(TermSupport, ASlowTermSizedOnTheLinesCountsItsSwitchesThere) {
  // A current idle on the first 2000 samples (the calibration line) that switches every 150
  // samples after them (the survey line): a slow term sized on the calibration rows alone saw no
  // switch; sized on the lines beside them too (fit.slow_lines), it saw 27 (on at sample 2000, then
  // every 150 samples from 2100 to 5950).
  Case c = make_case([](int i) { return i >= 2000 && (i / 150) % 2 ? 2.0 : 0.0; }, 0.1);
  Eigen::VectorXd line(c.flight.size());
  for (Eigen::Index i = 0; i < line.size(); ++i) line[i] = i < 2000 ? 1001.02 : 1001.1;
  c.flight.set("line", line);
  c.with_term.fit.lines = {1001.02};
  c.with_term.slow_terms = {"scalar:cur_x"};
  const std::vector<TermSupport> on_calibration = term_support(c.with_term, c.start, c.flight);
  ASSERT_EQ(on_calibration.size(), 1u);
  EXPECT_FALSE(on_calibration[0].on_lines);
  EXPECT_EQ(on_calibration[0].switches, 0);
  EXPECT_NE(support_note(on_calibration[0]).find("switched 0 times on the calibration rows:"),
            std::string::npos)
      << support_note(on_calibration[0]);
  c.with_term.fit.slow_lines = {1001.1};
  const std::vector<TermSupport> on_lines = term_support(c.with_term, c.start, c.flight);
  ASSERT_EQ(on_lines.size(), 1u);
  EXPECT_TRUE(on_lines[0].on_lines);
  EXPECT_EQ(on_lines[0].switches, 27);
  EXPECT_NE(support_note(on_lines[0], 30).find("on the calibration rows and the lines beside them"),
            std::string::npos)
      << support_note(on_lines[0], 30);
  EXPECT_EQ(support_note(on_lines[0]), "");
}

TEST(TermSupport, ATermWhoseChannelHasATwinSaysTheEffectMayBeEithers) {
  Case c = make_case([](int i) { return (i / 150) % 2 ? 2.0 : 0.0; }, 0.1);
  // A second tap of the same switched load (0.9 times it, its own noise of 0.05 A) and a load
  // switched out of step with it, both recorded, neither acting on the scalar.
  Eigen::VectorXd twin(c.flight.size()), other(c.flight.size());
  for (Eigen::Index i = 0; i < twin.size(); ++i) {
    twin[i] = 0.9 * c.flight.column("cur_x")[i] +
              0.05 * std::sqrt(3.0) * std::fmod(std::sin(78.233 * i) * 12345.678, 1.0);
    other[i] = ((i + 75) / 150) % 2 ? 2.0 : 0.0;
  }
  c.flight.set("cur_x_tap", twin);
  c.flight.set("cur_y", other);
  const std::vector<TermSupport> s = term_support(c.with_term, c.start, c.flight);
  ASSERT_EQ(s.size(), 1u);
  ASSERT_EQ(s[0].twins.size(), 1u);
  EXPECT_EQ(s[0].twins[0].channel, "cur_x");
  EXPECT_EQ(s[0].twins[0].twin, "cur_x_tap");
  EXPECT_GE(s[0].twins[0].correlation, kTwinCorrelation);
  const std::string note = twins_note(s[0]);
  EXPECT_NE(note.find("cannot tell cur_x from cur_x_tap"), std::string::npos) << note;
  EXPECT_NE(note.find("may be either's"), std::string::npos) << note;
  // Without the tap: no twin, nothing to say.
  c.flight.remove("cur_x_tap");
  const std::vector<TermSupport> alone = term_support(c.with_term, c.start, c.flight);
  ASSERT_EQ(alone.size(), 1u);
  EXPECT_TRUE(alone[0].twins.empty());
  EXPECT_EQ(twins_note(alone[0]), "");
}

TEST(TermSupport, TheJackknifeSigmaMatchesTheSpreadOverNoiseDrawsWhereTheFitsOwnUnderstatesIt) {
  // The current of 3 nT/A as a square wave of 300 samples, under a noise correlated in time (a
  // first-order process of 0.1 nT with a correlation of 0.98 per sample, about 5 s at 10 Hz): the
  // fit's residual is not white, so the fit's own covariance (white noise) understates the
  // coefficient's spread. Over 40 draws of the noise, the jackknife's sigma (20 blocks of the
  // fit rows) matches the spread of the fitted coefficient.
  const Model start = reference_tl16();
  const FlightData clean = test::synthetic_tl_flight(start, test::known_coefficients(16));
  Eigen::VectorXd x(clean.size());
  for (Eigen::Index i = 0; i < x.size(); ++i) x[i] = (i / 150) % 2 ? 2.0 : 0.0;
  std::vector<double> coef, jack, own;
  for (unsigned draw = 0; draw < 40; ++draw) {
    FlightData f = clean;
    std::mt19937_64 rng(1000 + draw);
    const Eigen::VectorXd noise = correlated_noise(f.size(), 0.1, 0.98, &rng);
    f.set("cur_x", x);
    f.mutable_column("mag_5_uc") += 3.0 * x + noise;
    Model m = start;
    m.add_term("scalar:cur_x");
    fit_model(m, {&f});
    const Eigen::Index j = m.coefficients.size() - 1;  // the current's coefficient
    ASSERT_EQ(m.column_names[static_cast<size_t>(j)], "scalar:cur_x");
    coef.push_back(m.coefficients[j]);
    const Eigen::MatrixXd cov = coefficient_jackknife_covariance(m, {&f});
    ASSERT_EQ(cov.rows(), m.coefficients.size());
    jack.push_back(std::sqrt(cov(j, j)));
    own.push_back(std::sqrt(m.report.coefficient_covariance(j, j)));
  }
  const auto mean = [](const std::vector<double>& v) {
    double s = 0;
    for (double e : v) s += e;
    return s / static_cast<double>(v.size());
  };
  const double m = mean(coef);
  double ss = 0;
  for (double c : coef) ss += (c - m) * (c - m);
  const double spread = std::sqrt(ss / static_cast<double>(coef.size() - 1));
  std::printf(
      "  coefficient %.4f nT/A (true 3): spread over draws %.4f, jackknife %.4f, fit's own "
      "%.4f\n",
      m, spread, mean(jack), mean(own));
  EXPECT_NEAR(m, 3.0, 3 * spread);
  EXPECT_GT(mean(jack), 0.6 * spread);
  EXPECT_LT(mean(jack), 1.5 * spread);
  EXPECT_LT(mean(own), 0.5 * spread);
}

TEST(TermSupport, ATermFittedOnCorrelatedNoiseAloneIsSaidNotToBeDetermined) {
  // The scalar holds TL and a noise correlated over about 5 s (0.3 nT); a slowly wandering
  // channel that acts on nothing is added as a term. The fit gives it a size; over blocks of the
  // fit rows that size is within two sigma of none, and the note says the term may stand in for
  // another effect. The same channel carrying 3 nT per unit needs no note.
  const Model start = reference_tl16();
  const FlightData clean = test::synthetic_tl_flight(start, test::known_coefficients(16));
  std::mt19937_64 rng(7);
  std::normal_distribution<double> normal(0.0, 1.0);
  Eigen::VectorXd noise(clean.size()), y(clean.size());
  double v = 0, w = 0;
  for (Eigen::Index i = 0; i < noise.size(); ++i) {
    v = 0.98 * v + 0.3 * std::sqrt(1 - 0.98 * 0.98) * normal(rng);
    w = 0.97 * w + 0.1 * normal(rng);
    noise[i] = v;
    y[i] = 5.0 + w;
  }
  for (const double gain : {0.0, 3.0}) {
    FlightData f = clean;
    f.set("cur_y", y);
    f.mutable_column("mag_5_uc") += gain * y + noise;
    Model tl = start;
    fit_model(tl, {&f});
    Model m = tl;
    m.add_term("scalar:cur_y");
    m.coefficients.resize(0);
    fit_model(m, {&f});
    const std::vector<TermSupport> s = term_support(m, tl, f);
    ASSERT_EQ(s.size(), 1u);
    const std::string note = support_note(s[0]);
    std::printf("  gain %.0f nT per unit: size %.3f nT +- %.3f nT; note: %s\n", gain, s[0].size_nT,
                s[0].size_sigma_nT, note.c_str());
    EXPECT_GE(s[0].switches, 10);  // it wanders over its range: not a matter of few switches
    if (gain == 0.0) {
      EXPECT_LT(s[0].size_nT, 2.0 * s[0].size_sigma_nT);
      EXPECT_NE(note.find("is not determined by the calibration rows"), std::string::npos) << note;
      EXPECT_NE(note.find("cur_y may stand in for another effect"), std::string::npos) << note;
    } else {
      EXPECT_NEAR(s[0].size_nT, 3.0 * std::sqrt((y.array() - y.mean()).square().mean()),
                  0.05 * s[0].size_nT);
      EXPECT_EQ(note, "");
    }
  }
}

TEST(TermSupport, AFieldTermsSizeIsWhatItAddsBeyondThePermanentFieldNotItsChannelsLevel) {
  // A body field of (2, -1, 1.5) nT per unit of a channel that switches by 1 unit every 150
  // samples, held at a level of 0 or of 27.5 units (a bus voltage). At 27.5 the term is mostly
  // 27.5 times the permanent columns, which the permanent coefficients take: its size, what it
  // adds to the model, is the same at both levels (its contribution's std over the flight would
  // be about 55 times larger at 27.5, its level times the direction cosines' swing).
  const Model start = reference_tl16();
  const FlightData clean = test::synthetic_tl_flight(start, test::known_coefficients(16));
  double size[2] = {0, 0}, sigma[2] = {0, 0};
  for (int k = 0; k < 2; ++k) {
    const double level = k == 0 ? 0.0 : 27.5;
    FlightData f = clean;
    Eigen::VectorXd v(f.size());
    for (Eigen::Index i = 0; i < v.size(); ++i)
      v[i] = level + ((i / 150) % 2 ? 0.5 : -0.5) +
             0.05 * std::fmod(std::sin(78.233 * i) * 43758.5453, 1.0);
    f.set("cur_v", v);
    Model m = start;
    m.add_term("field:cur_v");
    const Eigen::MatrixXd a = design_matrix(m, f);
    const Eigen::Index j = a.cols() - 3;  // the term's three columns come last
    ASSERT_EQ(m.column_names.empty() ? std::string("field:cur_v.x")
                                     : m.column_names[static_cast<size_t>(j)],
              "field:cur_v.x");
    f.mutable_column("mag_5_uc") +=
        2.0 * a.col(j) - 1.0 * a.col(j + 1) + 1.5 * a.col(j + 2) +
        Eigen::VectorXd::NullaryExpr(f.size(), [](Eigen::Index i) {
          return 0.05 * std::sqrt(3.0) * std::fmod(std::sin(12.9898 * i) * 43758.5453, 1.0);
        });
    Model tl = start;
    fit_model(tl, {&f});
    fit_model(m, {&f});
    const std::vector<TermSupport> s = term_support(m, tl, f);
    ASSERT_EQ(s.size(), 1u);
    size[k] = s[0].size_nT;
    sigma[k] = s[0].size_sigma_nT;
    std::printf("  level %.1f: size %.4f nT +- %.4f nT; note: %s\n", level, size[k], sigma[k],
                support_note(s[0]).c_str());
    EXPECT_EQ(support_note(s[0]), "");  // it switches 39 times and is well determined
  }
  EXPECT_GT(size[0], 0.1);
  EXPECT_NEAR(size[1], size[0], 0.02 * size[0]);
  EXPECT_NEAR(sigma[1], sigma[0], 0.5 * sigma[0]);
}

TEST(TermSupport, ATermAtTheLongestTimeConstantTheFlightTellsApartIsSaidToStandForADrift) {
  // The closed-form flight: 6000 samples at its own rate. The low-pass scan a flight allows ends
  // at a third of its span (parameter_grid); a term whose low-pass sits there cannot be told from
  // a slower one, so it stands for a drift; one a step below it on the scan is a response.
  Case c = make_case([](int i) { return (i / 150) % 2 ? 2.0 : 0.0; }, 0.1);
  const auto tt = c.flight.tt();
  const double span_s = tt[tt.size() - 1] - tt[0];
  const std::vector<double> grid = parameter_grid(TransformKind::LowPass, c.flight.dt_s(), span_s);
  ASSERT_GE(grid.size(), 3u);
  const double top_s = grid.back(), below_s = grid[grid.size() - 2];
  EXPECT_LE(top_s, span_s / 3 + 1e-6);
  const auto support_of = [&](double tau_s) {
    Model m = c.start;
    char spec[64];
    std::snprintf(spec, sizeof(spec), "scalar:cur_x|lp(%.6g)", tau_s);
    m.add_term(spec);
    m.coefficients.resize(0);
    fit_model(m, {&c.flight});
    const std::vector<TermSupport> s = term_support(m, c.start, c.flight);
    EXPECT_EQ(s.size(), 1u);
    return s.empty() ? TermSupport{} : s[0];
  };
  const TermSupport at_top = support_of(top_s), below = support_of(below_s);
  std::printf("  scan %.3g to %.4g s over a %.0f s flight: lp(%.4g) %s, lp(%.4g) %s\n",
              grid.front(), top_s, span_s, top_s, slow_edge_note(at_top).c_str(), below_s,
              slow_edge_note(below).empty() ? "no note" : "a note");
  EXPECT_NEAR(at_top.slowest_time_constant_s, top_s, 1e-3 * top_s);
  EXPECT_NE(slow_edge_note(at_top).find("cur_x"), std::string::npos);
  EXPECT_NE(slow_edge_note(at_top).find("--validate"), std::string::npos);
  EXPECT_TRUE(std::isnan(below.slowest_time_constant_s));
  EXPECT_EQ(slow_edge_note(below), "");
}

}  // namespace
}  // namespace magcomp
