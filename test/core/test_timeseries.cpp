// Time-series helpers: Catmull-Rom interpolation is exact for quadratics (central differences
// are their exact slopes), whole-sample shifts move samples exactly, and the ends are NaN or
// held as documented; Pearson's r, ranks and the correlation time match their closed forms.
#include <gtest/gtest.h>

#include <cmath>
#include <random>

#include "magcomp/core/math/correlation.h"
#include "magcomp/core/math/timeseries.h"

namespace magcomp {
namespace {

Eigen::VectorXd quadratic(Eigen::Index n) {
  Eigen::VectorXd x(n);
  for (Eigen::Index i = 0; i < n; ++i) x[i] = 3.0 - 0.5 * i + 0.25 * i * i;
  return x;
}

TEST(Timeseries, CubicInterpolationIsExactForAQuadraticInside) {
  const Eigen::VectorXd x = quadratic(20);
  for (double u : {1.0, 1.3, 4.5, 9.99, 17.25, 18.0}) {
    EXPECT_NEAR(cubic_at(x, u), 3.0 - 0.5 * u + 0.25 * u * u, 1e-12) << u;
  }
}

TEST(Timeseries, CubicInterpolationHoldsTheEndValuesBeyondTheEnds) {
  const Eigen::VectorXd x = quadratic(10);
  EXPECT_DOUBLE_EQ(cubic_at(x, -3.0), x[0]);
  EXPECT_DOUBLE_EQ(cubic_at(x, 12.5), x[9]);
  EXPECT_DOUBLE_EQ(cubic_at(x, 0.0), x[0]);
  EXPECT_DOUBLE_EQ(cubic_at(x, 9.0), x[9]);
}

TEST(Timeseries, AWholeSampleShiftMovesEverySampleExactly) {
  const Eigen::VectorXd x = quadratic(12);
  const Eigen::VectorXd late = shift_samples(x, 2.0);
  EXPECT_TRUE(std::isnan(late[0]));
  EXPECT_TRUE(std::isnan(late[1]));
  for (Eigen::Index i = 2; i < 12; ++i) EXPECT_EQ(late[i], x[i - 2]) << i;
  const Eigen::VectorXd early = shift_samples(x, -3.0);
  for (Eigen::Index i = 0; i < 9; ++i) EXPECT_EQ(early[i], x[i + 3]) << i;
  for (Eigen::Index i = 9; i < 12; ++i) EXPECT_TRUE(std::isnan(early[i])) << i;
  const Eigen::VectorXd held = shift_samples(x, 2.0, true);
  EXPECT_EQ(held[0], x[0]);
  EXPECT_EQ(held[1], x[0]);
  EXPECT_EQ(held[5], x[3]);
}

TEST(Timeseries, AFractionalShiftOfAQuadraticIsTheQuadraticShifted) {
  const Eigen::VectorXd x = quadratic(30);
  const double s = 0.37;
  const Eigen::VectorXd y = shift_samples(x, s);
  for (Eigen::Index i = 3; i < 27; ++i) {
    const double u = static_cast<double>(i) - s;
    EXPECT_NEAR(y[i], 3.0 - 0.5 * u + 0.25 * u * u, 1e-11) << i;
  }
}

// A pulse delayed by a fraction of a sample and realigned comes back smoothed (the round trip is
// not the identity), and lag_round_trip() gives any column that same smoothing; a whole-sample
// lag leaves the columns as they are.
TEST(Timeseries, TheLagRoundTripIsTheSmoothingOfARealignedFractionalDelay) {
  Eigen::VectorXd pulse = Eigen::VectorXd::Zero(40);
  pulse.segment(18, 3).setConstant(5.0);
  const double lag = 2.44;
  const Eigen::VectorXd realigned = shift_samples(shift_samples(pulse, lag, true), -lag, true);
  EXPECT_GT((realigned - pulse).cwiseAbs().maxCoeff(), 0.3);  // the record is not restored
  Eigen::MatrixXd cols(40, 2);
  cols << pulse, 2.0 * pulse;
  EXPECT_EQ(lag_round_trip_reach(lag), 3);
  lag_round_trip(cols, lag);
  for (Eigen::Index i = 0; i < 40; ++i) {
    EXPECT_EQ(cols(i, 0), realigned[i]) << i;
    EXPECT_NEAR(cols(i, 1), 2.0 * realigned[i], 1e-12) << i;
  }
  // Nothing moves more than 3 rows away: the pulse (rows 18-20) reaches rows 15-23 only.
  for (Eigen::Index i = 0; i < 40; ++i) {
    if (i < 15 || i > 23) {
      EXPECT_EQ(cols(i, 0), 0.0) << i;
    }
  }
  EXPECT_EQ(lag_round_trip_reach(3.0), 0);
  Eigen::MatrixXd whole(40, 1);
  whole << pulse;
  lag_round_trip(whole, 3.0);
  EXPECT_EQ(whole.col(0), pulse);
}

// The round trip of a slice with lag_round_trip_slice_margin() rows each side gives the slice's
// own rows the numbers of the whole column's round trip, for lags of a fraction of a sample to
// several samples, either sign; with only lag_round_trip_reach() rows, a lag of 3.79 samples
// gives the last rows the slice's held end instead.
TEST(Timeseries, ALagRoundTripOnASliceWithItsMarginEqualsTheWholeColumns) {
  const Eigen::Index n = 200, first = 80, last = 119;
  Eigen::VectorXd x(n);
  for (Eigen::Index i = 0; i < n; ++i) x[i] = std::sin(0.37 * i) + 0.01 * i * i;
  for (double lag : {0.3, 2.44, 3.79, -3.79, 7.5}) {
    Eigen::MatrixXd whole = x;
    lag_round_trip(whole, lag);
    const Eigen::Index m = lag_round_trip_slice_margin(lag);
    EXPECT_EQ(m, static_cast<Eigen::Index>(std::ceil(std::abs(lag))) + 3) << lag;
    Eigen::MatrixXd part = x.segment(first - m, last - first + 1 + 2 * m);
    lag_round_trip(part, lag);
    for (Eigen::Index i = first; i <= last; ++i)
      EXPECT_EQ(part(i - first + m, 0), whole(i, 0)) << "lag " << lag << " row " << i;
  }
  const double lag = 3.79;
  Eigen::MatrixXd whole = x;
  lag_round_trip(whole, lag);
  const Eigen::Index r = lag_round_trip_reach(lag);
  Eigen::MatrixXd part = x.segment(first - r, last - first + 1 + 2 * r);
  lag_round_trip(part, lag);
  EXPECT_GT(std::abs(part(last - first + r, 0) - whole(last, 0)), 0.1);
  EXPECT_EQ(lag_round_trip_slice_margin(4.0), 0);
}

TEST(Timeseries, CentralRateIsExactOnALineAndWrapsAnAngleAcrossPi) {
  Eigen::VectorXd x(6);
  x << 1.0, 3.0, 5.0, 7.0, 9.0, 11.0;  // 2 per sample, 0.5 s apart: 4 per s
  const Eigen::VectorXd d = central_rate(x, 0.5);
  for (Eigen::Index i = 0; i < 6; ++i) EXPECT_NEAR(d[i], 4.0, 1e-12) << i;
  Eigen::VectorXd yaw(3);  // 0.1 rad per sample across +-pi
  yaw << M_PI - 0.1, -M_PI, -M_PI + 0.1;
  const Eigen::VectorXd w = central_rate(yaw, 1.0, true);
  for (Eigen::Index i = 0; i < 3; ++i) EXPECT_NEAR(w[i], 0.1, 1e-12) << i;
  EXPECT_NEAR(central_rate(yaw, 1.0)[1], -(2 * M_PI - 0.2) / 2, 1e-12);  // unwrapped: the jump
}

}  // namespace
}  // namespace magcomp

TEST(Timeseries, MovingAverageIsTheCentredMeanOfTheFiniteValuesAndShortensAtTheEnds) {
  Eigen::VectorXd x(7);
  x << 1, 2, NAN, 4, 5, 6, 7;
  const Eigen::VectorXd m = magcomp::moving_average(x, 1);
  EXPECT_DOUBLE_EQ(m[0], 1.5);  // (1 + 2) / 2: the window is cut at the start
  EXPECT_DOUBLE_EQ(m[1], 1.5);  // the NaN is left out, not counted as 0
  EXPECT_DOUBLE_EQ(m[2], 3.0);  // (2 + 4) / 2
  EXPECT_DOUBLE_EQ(m[4], 5.0);
  EXPECT_DOUBLE_EQ(m[6], 6.5);
  EXPECT_EQ(magcomp::moving_average(x, 0)[3], 4.0);  // a window of one sample is the sample
  Eigen::VectorXd gap(3);
  gap << NAN, NAN, NAN;
  EXPECT_TRUE(std::isnan(magcomp::moving_average(gap, 1)[1]));
}

TEST(Correlation, PearsonAndRanksInClosedForm) {
  // Pearson's r of a line with itself rescaled is +-1, of anything with a constant 0; ranks are
  // 0-based with ties given their average (Spearman's rho is pearson() of ranks).
  Eigen::VectorXd x(5), y(5), c(5);
  x << 1.0, 4.0, 2.0, 8.0, 5.0;
  y = 3.0 * x.array() - 7.0;
  c.setConstant(2.5);
  EXPECT_NEAR(magcomp::pearson(x, y), 1.0, 1e-15);
  EXPECT_NEAR(magcomp::pearson(x, -y), -1.0, 1e-15);
  EXPECT_EQ(magcomp::pearson(x, c), 0.0);
  // x and its squares: r from the sums by hand, 0.9856..., rho 1 (the same order).
  const Eigen::VectorXd x2 = x.array().square();
  const double mx = x.mean(), my = x2.mean();
  const double sxy = ((x.array() - mx) * (x2.array() - my)).sum();
  const double sxx = (x.array() - mx).square().sum(), syy = (x2.array() - my).square().sum();
  EXPECT_NEAR(magcomp::pearson(x, x2), sxy / std::sqrt(sxx * syy), 1e-15);
  EXPECT_LT(magcomp::pearson(x, x2), 0.999);
  EXPECT_NEAR(magcomp::pearson(magcomp::ranks(x), magcomp::ranks(x2)), 1.0, 1e-15);
  Eigen::VectorXd t(4);
  t << 3.0, 1.0, 3.0, 2.0;
  const Eigen::VectorXd r = magcomp::ranks(t);
  EXPECT_EQ(r[0], 2.5);
  EXPECT_EQ(r[1], 0.0);
  EXPECT_EQ(r[2], 2.5);
  EXPECT_EQ(r[3], 1.0);
}

TEST(Correlation, PearsonWhereFiniteLeavesOutTheRowsWhereEitherIsNaN) {
  // A line and the line rescaled, with a NaN in each at different rows and a wild value that
  // only a NaN row of the other hides: r over the three rows both hold is exactly 1.
  Eigen::VectorXd a(5), b(5);
  a << 1.0, NAN, 3.0, 1000.0, 5.0;
  b << 2.0, 4.0, 6.0, NAN, 10.0;
  EXPECT_NEAR(magcomp::pearson_where_finite(a, b, 3), 1.0, 1e-15);
  EXPECT_TRUE(std::isnan(magcomp::pearson_where_finite(a, b, 4)));  // three rows, four asked
  b[3] = 8.0;                                                       // now the wild row counts
  EXPECT_LT(magcomp::pearson_where_finite(a, b, 3), 0.9);
}

TEST(Correlation, TheCorrelationTimeOfASineAndOfLowPassedNoiseInClosedForm) {
  // A sine of period P: its autocorrelation is cos(2 pi lag / P), whose integral up to the first
  // zero (P / 4) is P / (2 pi). Sampled at 10 Hz over 10 h (the estimate's end effect, 1 - lag/N,
  // is below 1e-4 there).
  const double dt_s = 0.1, period_s = 120.0;
  const Eigen::Index n = 360000;
  Eigen::VectorXd sine(n);
  for (Eigen::Index i = 0; i < n; ++i)
    sine[i] = 3.0 * std::sin(2 * M_PI * static_cast<double>(i) * dt_s / period_s) + 7.0;
  EXPECT_NEAR(magcomp::correlation_time_s(sine, dt_s), period_s / (2 * M_PI),
              0.02 * period_s / (2 * M_PI));
  // A first-order low-pass of white noise with time constant tau: exp(-lag / tau), integral tau.
  // 10 h hold 600 such times: the estimate's own scatter is a few per cent.
  std::mt19937 rng(7);
  std::normal_distribution<double> white(0.0, 1.0);
  const double tau_s = 30.0, a = std::exp(-dt_s / tau_s);
  Eigen::VectorXd noise(n);
  double y = 0;
  for (Eigen::Index i = 0; i < n; ++i) noise[i] = y = a * y + (1 - a) * white(rng);
  EXPECT_NEAR(magcomp::correlation_time_s(noise, dt_s), tau_s, 0.15 * tau_s);
  // Every tenth sample missing: the same within the scatter; a constant has none.
  for (Eigen::Index i = 0; i < n; i += 10) noise[i] = NAN;
  EXPECT_NEAR(magcomp::correlation_time_s(noise, dt_s), tau_s, 0.15 * tau_s);
  EXPECT_EQ(magcomp::correlation_time_s(Eigen::VectorXd::Constant(100, 4.0), dt_s), 0.0);
  // A ramp's autocorrelation never falls to 0 before half its length: it is as slow as it can be.
  const Eigen::VectorXd ramp = Eigen::VectorXd::LinSpaced(1000, 0.0, 1.0);
  EXPECT_GT(magcomp::correlation_time_s(ramp, dt_s), 0.15 * 1000 * dt_s);
}
