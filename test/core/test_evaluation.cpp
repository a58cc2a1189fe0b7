// Error statistics against hand-computed values: per line (mean removed, n - 1) and pooled
// (each line's mean removed, over n), the raw RMS, NaN samples counted and left out.
#include <gtest/gtest.h>

#include <cmath>

#include "magcomp/core/evaluate/evaluation.h"

namespace magcomp {
namespace {

TEST(Evaluation, StatisticsPerLineAndPooledEqualTheHandComputedOnes) {
  // Line 1: errors 1, 3 (mean 2); line 2: -1 four times (mean -1); one NaN on line 2.
  const Eigen::Index n = 7;
  Eigen::VectorXd tt(n), line(n), error(n);
  const double lines[] = {1, 1, 2, 2, 2, 2, 2};
  const double errors[] = {1, 3, -1, -1, NAN, -1, -1};
  for (Eigen::Index i = 0; i < n; ++i) {
    tt[i] = static_cast<double>(i);
    line[i] = lines[i];
    error[i] = errors[i];
  }
  FlightData f;
  f.set("tt", tt);
  f.set("line", line);
  const Evaluation ev = error_statistics(f, error, false);
  EXPECT_EQ(ev.n, 6);
  EXPECT_EQ(ev.nan_samples, 1);
  ASSERT_EQ(ev.per_line.size(), 2u);
  EXPECT_EQ(ev.per_line[0].line, 1.0);
  EXPECT_EQ(ev.per_line[0].n, 2);
  EXPECT_NEAR(ev.per_line[0].std_nT, std::sqrt(2.0), 1e-12);   // (1 + 1) / (2 - 1)
  EXPECT_NEAR(ev.per_line[0].rmse_nT, std::sqrt(5.0), 1e-12);  // (1 + 9) / 2
  EXPECT_EQ(ev.per_line[1].n, 4);
  EXPECT_NEAR(ev.per_line[1].std_nT, 0.0, 1e-12);
  EXPECT_NEAR(ev.per_line[1].rmse_nT, 1.0, 1e-12);
  EXPECT_NEAR(ev.rmse_nT, std::sqrt(14.0 / 6.0), 1e-12);  // (1 + 9 + 4) / 6
  EXPECT_NEAR(ev.std_nT, std::sqrt(2.0 / 6.0), 1e-12);    // deviations 1, 1, 0, 0, 0, 0
  EXPECT_NEAR(pooled_std(error, line), ev.std_nT, 1e-12);
}

TEST(Evaluation, WithoutALineFieldTheFlightIsOneGroup) {
  Eigen::VectorXd tt(4), error(4);
  tt << 0, 1, 2, 3;
  error << 2, 4, 6, 8;
  FlightData f;
  f.set("tt", tt);
  const Evaluation ev = error_statistics(f, error, false);
  ASSERT_EQ(ev.per_line.size(), 1u);
  EXPECT_NEAR(ev.per_line[0].std_nT, std::sqrt(20.0 / 3.0), 1e-12);  // mean 5
  EXPECT_NEAR(ev.std_nT, std::sqrt(20.0 / 4.0), 1e-12);
  EXPECT_NEAR(ev.rmse_nT, std::sqrt(120.0 / 4.0), 1e-12);
}

}  // namespace
}  // namespace magcomp
