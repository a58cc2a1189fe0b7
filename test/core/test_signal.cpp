// The signal grammar and its transforms: parsing, closed-form responses, stream = batch.
#include <gtest/gtest.h>

#include <cmath>
#include <limits>

#include "magcomp/core/error.h"
#include "magcomp/core/model/signal.h"

namespace magcomp {
namespace {

Eigen::VectorXd times(Eigen::Index n, double dt) {
  Eigen::VectorXd t(n);
  for (Eigen::Index i = 0; i < n; ++i) t[i] = 1000.0 + dt * static_cast<double>(i);
  return t;
}

Eigen::VectorXd run(const std::string& text, const Eigen::VectorXd& t, const Eigen::VectorXd& x) {
  return apply_transforms(parse_signal(text, text).transforms, t, x).col(0);
}

TEST(Signal, ParsesAndWritesBackTheCanonicalText) {
  for (const std::string s :
       {"cur_heat", "cur_heat|pow(2)|lp(150)", "B|decay(0.8)", "cur_a*ins_acc_z|d",
        "vol_x|hp(30)|delay(0.5)|abs", "cur_heat|lp(?)", "x|int|hp(600)"}) {
    EXPECT_EQ(parse_signal(s, s).str(), s);
  }
  EXPECT_EQ(parse_signal(" cur_heat | lowpass(150) ", "t").str(), "cur_heat|lp(150)");
  const SignalExpr e = parse_signal("B*cur_x|d|lp(?)", "t");
  EXPECT_EQ(e.width(), 3);
  EXPECT_EQ(e.lookahead(), 1);
  EXPECT_TRUE(e.has_free());
  EXPECT_EQ(parse_signal("x|decay(1)|d", "t").lookahead(), 2);
}

TEST(Signal, BadTextGivesOneLineNamingTheTerm) {
  const std::vector<std::pair<std::string, std::string>> cases = {
      {"", "empty signal"},
      {"cur heat|lp(3)", ""},  // spaces are dropped: "curheat" is fine
      {"cur-heat", "is not a field name"},
      {"x|lp", "needs a parameter"},
      {"x|lp(abc)", "is not a number"},
      {"x|lp(-3)", "time constant must be in (0, 1e6] s"},
      {"x|lp(nan)", "must be finite"},
      {"x|delay(1e9)", "delay must be in [0, 3600] s"},
      {"x|pow(0)", "exponent must be non-zero"},
      {"x|d(3)", "takes no parameter"},
      {"x|smooth(3)", "unknown transform 'smooth'"},
      {"B*B", "at most one vector source"}};
  for (const auto& [text, why] : cases) {
    if (why.empty()) {
      EXPECT_NO_THROW(parse_signal(text, "field:" + text));
      continue;
    }
    try {
      parse_signal(text, "field:" + text);
      ADD_FAILURE() << text;
    } catch (const Error& e) {
      const std::string m = e.what();
      EXPECT_NE(m.find("term 'field:" + text + "'"), std::string::npos) << m;
      EXPECT_NE(m.find(why), std::string::npos) << m;
      EXPECT_EQ(m.find('\n'), std::string::npos) << m;
    }
  }
}

TEST(Signal, TransformsMatchTheirClosedForms) {
  const double dt = 0.1;
  const Eigen::Index n = 2001;
  const Eigen::VectorXd t = times(n, dt);
  // A unit step at sample 1 through lp(5): 1 - exp(-(t - t1)/5) exactly (the recursion is exact
  // for a held input).
  Eigen::VectorXd step = Eigen::VectorXd::Ones(n);
  step[0] = 0.0;
  const Eigen::VectorXd lp = run("x|lp(5)", t, step);
  const Eigen::VectorXd hp = run("x|hp(5)", t, step);
  for (Eigen::Index i = 1; i < n; ++i) {
    const double expected = 1.0 - std::exp(-(t[i] - t[0]) / 5.0) * 1.0;
    // y0 = 0, then y_i = a y_{i-1} + (1 - a): y_i = 1 - a^i
    EXPECT_NEAR(lp[i], 1.0 - std::pow(std::exp(-dt / 5.0), static_cast<double>(i)), 1e-12);
    EXPECT_NEAR(lp[i], expected, 1e-9);
    EXPECT_NEAR(hp[i], 1.0 - lp[i], 1e-12);
  }
  // A ramp 3 t: derivative 3 everywhere (ends included), integral 1.5 (t - t0)², delay 2 s.
  const Eigen::VectorXd ramp = 3.0 * (t.array() - t[0]).matrix();
  const Eigen::VectorXd d = run("x|d", t, ramp);
  const Eigen::VectorXd in = run("x|int", t, ramp);
  const Eigen::VectorXd dl = run("x|delay(2)", t, ramp);
  for (Eigen::Index i = 0; i < n; ++i) {
    const double tau = t[i] - t[0];
    EXPECT_NEAR(d[i], 3.0, 1e-9) << i;
    EXPECT_NEAR(in[i], 1.5 * tau * tau, 1e-8) << i;
    EXPECT_NEAR(dl[i], tau >= 2.0 ? 3.0 * (tau - 2.0) : 0.0, 1e-9) << i;
  }
  // pow and abs: an integer exponent keeps the sign, a fractional one takes |x|.
  Eigen::VectorXd x(3);
  x << -2.0, 0.5, 3.0;
  const Eigen::VectorXd t3 = times(3, dt);
  EXPECT_DOUBLE_EQ(run("x|pow(3)", t3, x)[0], -8.0);
  EXPECT_DOUBLE_EQ(run("x|pow(2)", t3, x)[0], 4.0);
  EXPECT_DOUBLE_EQ(run("x|pow(0.5)", t3, x)[0], std::sqrt(2.0));
  EXPECT_DOUBLE_EQ(run("x|abs", t3, x)[0], 2.0);
  // decay(tau) of a ramp settles to the ramp's slope (a response to the rate).
  EXPECT_NEAR(run("x|decay(0.5)", t, ramp)[n - 1], 3.0, 1e-9);
}

TEST(Signal, PlayIsTheBacklashOperator) {
  // Half-width 1: the output stays until the input has moved 1 past it, then follows at 1 behind.
  const Eigen::VectorXd t = times(13, 0.1);
  Eigen::VectorXd x(13), expected(13);
  x << 0, 1, 2, 3, 2, 1, 0, -1, -2, -1, 0, 1, 2;
  expected << 0, 0, 1, 2, 2, 2, 1, 0, -1, -1, -1, 0, 1;
  EXPECT_EQ(run("x|play(1)", t, x), expected);
  EXPECT_EQ(run("x|play(0)", t, x), x);  // no play: the input itself
  // Its half-width is a fitted parameter like every '?', and a negative one is refused.
  EXPECT_TRUE(parse_signal("x|play(?)", "t").has_free());
  EXPECT_THROW(parse_signal("x|play(-1)", "t"), Error);
}

TEST(Signal, SaturationAndStepAreStaticLaws) {
  const Eigen::VectorXd t = times(5, 0.1);
  Eigen::VectorXd x(5);
  x << -4, -0.01, 0, 0.01, 4;
  const Eigen::VectorXd sat = run("x|sat(2)", t, x);
  for (Eigen::Index i = 0; i < 5; ++i) EXPECT_DOUBLE_EQ(sat[i], 2 * std::tanh(x[i] / 2));
  EXPECT_NEAR(sat[3], 0.01, 1e-6);  // linear near 0
  EXPECT_NEAR(sat[4], 2 * 0.9640275800758169, 1e-12);
  Eigen::VectorXd on(5);
  on << 0, 0, 0, 1, 1;
  EXPECT_EQ(run("x|step(0)", t, x), on);  // on strictly above the threshold
  EXPECT_TRUE(parse_signal("x|step(?)", "t").has_free());
  EXPECT_TRUE(parse_signal("x|step(-3)", "t").transforms[0].param == -3);
  EXPECT_THROW(parse_signal("x|sat(0)", "t"), Error);
}

TEST(Signal, ARampIsAHingeAndHingesSumToAPiecewiseLinearLaw) {
  const Eigen::VectorXd t = times(6, 0.1);
  Eigen::VectorXd x(6);
  x << -2, 0, 0.5, 1, 3, NAN;
  const Eigen::VectorXd r = run("x|ramp(0.5)", t, x);
  for (Eigen::Index i = 0; i < 5; ++i) EXPECT_DOUBLE_EQ(r[i], std::max(x[i] - 0.5, 0.0));
  EXPECT_TRUE(std::isnan(r[5]));
  // 2 ramp(0) - 3 ramp(1): slope 2 from 0 to 1, then -1: the law 0, 0, 1, 2, 0 at the samples.
  const Eigen::VectorXd law = 2 * run("x|ramp(0)", t, x) - 3 * run("x|ramp(1)", t, x);
  EXPECT_DOUBLE_EQ(law[0], 0.0);
  EXPECT_DOUBLE_EQ(law[2], 1.0);
  EXPECT_DOUBLE_EQ(law[3], 2.0);
  EXPECT_DOUBLE_EQ(law[4], 0.0);
  EXPECT_EQ(parse_signal("x|ramp(-1.5)|lp(3)", "t").str(), "x|ramp(-1.5)|lp(3)");
  EXPECT_THROW(parse_signal("x|ramp(inf)", "t"), Error);
}

TEST(Signal, NanPassesThroughAndTheStateWaits) {
  const Eigen::VectorXd t = times(6, 1.0);
  Eigen::VectorXd x(6);
  x << 1, 1, NAN, 1, 1, 1;
  const Eigen::VectorXd lp = run("x|lp(2)", t, x);
  EXPECT_TRUE(std::isnan(lp[2]));
  EXPECT_DOUBLE_EQ(lp[3], 1.0);  // the state skipped the NaN sample
  const Eigen::VectorXd in = run("x|int", t, x);
  EXPECT_TRUE(std::isnan(in[2]));
  EXPECT_DOUBLE_EQ(in[3], 1.0 + 2.0);  // the trapezoid spans the NaN: (1 + 1) / 2 * 2 s
}

TEST(Signal, AStreamEqualsTheBatchForEveryTransformExactly) {
  // An irregular time base and a noisy input with a NaN: the stream must be bit-identical.
  const Eigen::Index n = 3000;
  Eigen::VectorXd t(n), x(n);
  double tt = 500.0;
  for (Eigen::Index i = 0; i < n; ++i) {
    tt += 0.1 + 0.003 * std::sin(0.7 * static_cast<double>(i));
    t[i] = tt;
    x[i] = std::sin(0.01 * static_cast<double>(i)) + 0.3 * std::cos(0.37 * static_cast<double>(i));
  }
  x[1234] = NAN;
  for (const std::string s :
       {"x|d", "x|int", "x|abs", "x|lp(3)", "x|hp(40)", "x|delay(0.75)", "x|pow(2)", "x|pow(1.5)",
        "x|decay(0.8)", "x|pow(2)|lp(150)", "x|d|d", "x|int|hp(100)|delay(0.3)", "x|play(0.4)",
        "x|play(0.2)|lp(20)", "x|sat(0.5)", "x|step(0.2)|lp(5)", "x|ramp(0.1)|lp(30)"}) {
    const SignalExpr e = parse_signal(s, s);
    const Eigen::VectorXd batch = apply_transforms(e.transforms, t, x).col(0);
    TransformChain chain(e.transforms);
    std::vector<std::pair<double, double>> out;
    auto emit = [&](double ts, double y) { out.emplace_back(ts, y); };
    for (Eigen::Index i = 0; i < n; ++i) {
      chain.push(t[i], x[i], emit);
      // Latency: at most lookahead() samples behind the input.
      EXPECT_GE(static_cast<long>(out.size()), static_cast<long>(i + 1 - e.lookahead())) << s;
    }
    chain.flush(emit);
    ASSERT_EQ(static_cast<Eigen::Index>(out.size()), n) << s;
    for (Eigen::Index i = 0; i < n; ++i) {
      ASSERT_EQ(out[static_cast<size_t>(i)].first, t[i]) << s;
      const double a = out[static_cast<size_t>(i)].second, b = batch[i];
      if (std::isnan(b)) {
        ASSERT_TRUE(std::isnan(a)) << s << " " << i;
      } else {
        ASSERT_EQ(a, b) << s << " at " << i;  // bit-identical
      }
    }
  }
}

TEST(Signal, AShortOrGappedSeriesGivesTheStreamsValuesExactly) {
  // The batch runs transform by transform; the stream runs every transform per sample. Series of
  // one, two and three samples, NaN first and in runs, a delay after a derivative and before one:
  // each must give the stream's values bit for bit.
  const std::vector<std::string> chains = {
      "x|d",          "x|d|delay(0.25)|lp(2)", "x|delay(0.35)|d", "x|decay(0.5)|delay(0.1)",
      "x|int|d",      "x|play(0.3)|d|lp(1)",   "x|hp(3)|pow(3)",  "x|delay(0.1)|step(0.1)|lp(4)",
      "x|sat(2)|int", "x|ramp(-0.2)|decay(2)"};
  for (const Eigen::Index n : {1, 2, 3, 40}) {
    Eigen::VectorXd t(n), x(n);
    for (Eigen::Index i = 0; i < n; ++i) {
      t[i] = 10.0 + 0.1 * static_cast<double>(i) + (i % 3 == 2 ? 0.02 : 0.0);
      x[i] = std::cos(0.9 * static_cast<double>(i)) - 0.2;
    }
    x[0] = NAN;
    if (n > 10) x.segment(5, 4).setConstant(NAN);
    for (const std::string& s : chains) {
      const SignalExpr e = parse_signal(s, s);
      const Eigen::VectorXd batch = apply_transforms(e.transforms, t, x).col(0);
      TransformChain chain(e.transforms);
      std::vector<double> out;
      auto emit = [&](double, double y) { out.push_back(y); };
      for (Eigen::Index i = 0; i < n; ++i) chain.push(t[i], x[i], emit);
      chain.flush(emit);
      ASSERT_EQ(static_cast<Eigen::Index>(out.size()), n) << s;
      for (Eigen::Index i = 0; i < n; ++i) {
        const double a = out[static_cast<size_t>(i)], b = batch[i];
        if (std::isnan(a)) {
          EXPECT_TRUE(std::isnan(b)) << s << " n " << n << " at " << i;
        } else {
          EXPECT_EQ(a, b) << s << " n " << n << " at " << i;
        }
      }
    }
  }
}

}  // namespace
}  // namespace magcomp
