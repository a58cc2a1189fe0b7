// Butterworth filters against closed-form facts and scipy's published design.
#include <gtest/gtest.h>

#include <cmath>

#include "magcomp/core/error.h"
#include "magcomp/core/math/butterworth.h"

namespace magcomp {
namespace {

// Expands the cascade into one numerator and one denominator polynomial.
std::pair<std::vector<double>, std::vector<double>> expand(const std::vector<Biquad>& sos) {
  std::vector<double> b = {1.0}, a = {1.0};
  auto mul = [](const std::vector<double>& p, const std::array<double, 3>& q) {
    std::vector<double> r(p.size() + 2, 0.0);
    for (size_t i = 0; i < p.size(); ++i)
      for (size_t j = 0; j < 3; ++j) r[i + j] += p[i] * q[j];
    return r;
  };
  for (const auto& s : sos) {
    b = mul(b, s.b);
    a = mul(a, s.a);
  }
  return {b, a};
}

TEST(Butterworth, BandPassTransferFunctionEqualsScipy) {
  // scipy.signal.butter(4, [0.1, 0.9], btype='band', fs=10) (scipy 1.10.1).
  const std::vector<double> b_ref = {0.00223489169808233, 0, -0.00893956679232931, 0,
                                     0.01340935018849396, 0, -0.00893956679232931, 0,
                                     0.00223489169808233};
  const std::vector<double> a_ref = {1.0,
                                     -6.5715072754461925,
                                     19.030138916000173,
                                     -31.754413014587726,
                                     33.421633988809134,
                                     -22.73087042070526,
                                     9.757330177244835,
                                     -2.4167663056152353,
                                     0.26445481644350444};
  const Butterworth bp = Butterworth::band_pass(4, 0.1, 0.9, 10.0);
  EXPECT_EQ(bp.sections().size(), 4u);
  auto [b, a] = expand(bp.sections());
  for (size_t i = 0; i < 9; ++i) {
    EXPECT_NEAR(b[i], b_ref[i], 1e-12) << "b" << i;
    EXPECT_NEAR(a[i], a_ref[i], 1e-10) << "a" << i;
  }
}

TEST(Butterworth, MinusThreeDecibelsAtCutoffsAndUnityInBand) {
  const double half_power = 1.0 / std::sqrt(2.0);
  const Butterworth bp = Butterworth::band_pass(4, 0.1, 0.9, 10.0);
  EXPECT_NEAR(bp.magnitude(0.1), half_power, 1e-9);
  EXPECT_NEAR(bp.magnitude(0.9), half_power, 1e-9);
  EXPECT_LT(bp.magnitude(0.0), 1e-12);  // DC rejected
  EXPECT_LT(bp.magnitude(5.0), 1e-12);  // Nyquist rejected
  EXPECT_GT(bp.magnitude(0.3), 0.999);
  const Butterworth lp = Butterworth::low_pass(5, 1.0, 10.0);
  EXPECT_NEAR(lp.magnitude(0.0), 1.0, 1e-12);
  EXPECT_NEAR(lp.magnitude(1.0), half_power, 1e-9);
  EXPECT_LT(lp.magnitude(5.0), 1e-12);
  const Butterworth hp = Butterworth::high_pass(3, 0.5, 10.0);
  EXPECT_NEAR(hp.magnitude(5.0), 1.0, 1e-12);
  EXPECT_NEAR(hp.magnitude(0.5), half_power, 1e-9);
  EXPECT_LT(hp.magnitude(0.0), 1e-12);
}

TEST(Butterworth, FiltfiltEqualsScipySosfiltfilt) {
  Eigen::VectorXd x(200);
  for (int i = 0; i < 200; ++i) x[i] = std::sin(i * 0.3) + 0.1 * std::pow(i, 1.5) / 100.0;
  const Eigen::VectorXd y = Butterworth::band_pass(4, 0.1, 0.9, 10.0).filtfilt(x);
  // scipy.signal.sosfiltfilt(butter(4, [0.1, 0.9], 'band', fs=10, output='sos'), x)
  EXPECT_NEAR(y[0], 0.05434372250588193, 1e-9);
  EXPECT_NEAR(y[1], 0.33489482030034035, 1e-9);
  EXPECT_NEAR(y[50], 0.6562487846812369, 1e-9);
  EXPECT_NEAR(y[100], -1.0222653179166423, 1e-9);
  EXPECT_NEAR(y[199], -0.2593525711996695, 1e-9);
}

TEST(Butterworth, AFewColumnsAreFilteredAsTheScalarFilterAndAsAWideBlock) {
  // The band-pass of 1 to 4 columns (a candidate term's) runs a fixed-size pass; 5 or more, the
  // general loop; one column alone, the scalar filter. All three give the same values: the first
  // two to the bit (the same operations in the same order), the scalar one to 1e-12.
  const int n = 3000;
  Eigen::MatrixXd x(n, 6);
  for (int i = 0; i < n; ++i)
    for (int c = 0; c < 6; ++c)
      x(i, c) = std::sin(i * (0.05 + 0.07 * c)) + 0.3 * std::cos(i * 0.011 * (c + 1)) + c;
  for (const int order : {4, 2}) {  // order 4: four sections (the fixed pass); 2: the general one
    const Butterworth bp = Butterworth::band_pass(order, 0.1, 0.9, 10.0);
    const Eigen::MatrixXd wide = bp.filtfilt(Eigen::Ref<const Eigen::MatrixXd>(x));
    for (int k = 1; k <= 4; ++k) {
      const Eigen::MatrixXd narrow = bp.filtfilt(Eigen::Ref<const Eigen::MatrixXd>(x.leftCols(k)));
      ASSERT_EQ(narrow.rows(), n);
      EXPECT_EQ((narrow - wide.leftCols(k)).cwiseAbs().maxCoeff(), 0.0) << order << " " << k;
    }
    const Eigen::VectorXd one = bp.filtfilt(Eigen::VectorXd(x.col(2)));
    EXPECT_LT((one - wide.col(2)).cwiseAbs().maxCoeff(), 1e-12) << order;
    EXPECT_GT(wide.col(2).cwiseAbs().maxCoeff(), 0.1);  // the band's sines pass
  }
}

TEST(Butterworth, ZeroPhaseAndRejection) {
  const double fs = 10.0, f = 0.4;
  const int n = 4000;
  Eigen::VectorXd x(n), dc(n), nyq(n);
  for (int i = 0; i < n; ++i) {
    x[i] = std::sin(2 * M_PI * f * i / fs);
    dc[i] = 7.0;
    nyq[i] = (i % 2) ? 1.0 : -1.0;
  }
  const Butterworth bp = Butterworth::band_pass(4, 0.1, 0.9, fs);
  const double gain = std::pow(bp.magnitude(f), 2);  // forward-backward squares the magnitude
  const Eigen::VectorXd y = bp.filtfilt(x);
  // Away from the ends (the 0.1 Hz edge transient decays over ~100 s) output = |H|^2 input, no lag.
  for (int i = 1000; i < n - 1000; ++i) ASSERT_NEAR(y[i], gain * x[i], 1e-6) << i;
  EXPECT_LT(bp.filtfilt(dc).cwiseAbs().maxCoeff(), 1e-9);
  EXPECT_LT(bp.filtfilt(nyq).segment(1000, n - 2000).cwiseAbs().maxCoeff(), 1e-6);
}

TEST(Butterworth, StreamingEqualsBatchCausal) {
  const Butterworth lp = Butterworth::low_pass(4, 0.5, 10.0);
  Eigen::VectorXd x(500);
  for (int i = 0; i < 500; ++i) x[i] = 3.0 + std::cos(i * 0.05) + ((i * 7919) % 13) * 0.01;
  const Eigen::VectorXd batch = lp.filter(x);
  StreamingFilter s(lp);
  for (int i = 0; i < 500; ++i) ASSERT_DOUBLE_EQ(s.step(x[i]), batch[i]) << i;
  // Steady state: a constant input passes unchanged from the first sample.
  StreamingFilter c(lp);
  for (int i = 0; i < 10; ++i) EXPECT_NEAR(c.step(42.0), 42.0, 1e-9);
  c.reset();
  EXPECT_NEAR(c.step(-5.0), -5.0, 1e-9);
}

TEST(Butterworth, BadParametersNameTheParameter) {
  try {
    Butterworth::band_pass(4, 0.1, 6.0, 10.0);
    FAIL();
  } catch (const Error& e) {
    EXPECT_NE(std::string(e.what()).find("high cut-off"), std::string::npos) << e.what();
  }
  EXPECT_THROW(Butterworth::low_pass(0, 1.0, 10.0), Error);
  EXPECT_THROW(Butterworth::band_pass(4, 0.9, 0.1, 10.0), Error);
}

}  // namespace
}  // namespace magcomp
