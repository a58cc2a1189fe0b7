// The delete-a-block jackknife: its replicates are the fits without each block, and its std
// matches the spread of least-squares fits over draws of a correlated noise, which the
// independent-rows formula understates.
#include <gtest/gtest.h>

#include <Eigen/Dense>
#include <cmath>
#include <random>

#include "magcomp/core/fit/block_jackknife.h"
#include "magcomp/core/fit/parameter_fit.h"

namespace magcomp {
namespace {

// Columns of a fit: a slow sine, a step, a faster sine (M rows).
Eigen::MatrixXd columns(Eigen::Index m) {
  Eigen::MatrixXd x(m, 3);
  for (Eigen::Index i = 0; i < m; ++i) {
    const double t = static_cast<double>(i) / static_cast<double>(m);
    x(i, 0) = std::sin(2 * M_PI * 3 * t);
    x(i, 1) = t > 0.5 ? 1.0 : 0.0;
    x(i, 2) = std::cos(2 * M_PI * 11 * t);
  }
  return x;
}

TEST(BlockJackknife, ReplicatesAreTheFitsWithoutEachBlock) {
  const Eigen::Index m = 1003;  // blocks of 100 and 101 rows
  const Eigen::MatrixXd x = columns(m);
  std::mt19937_64 rng(5);
  std::normal_distribution<double> g(0, 0.3);
  Eigen::VectorXd y(m);
  for (Eigen::Index i = 0; i < m; ++i) y[i] = x.row(i).dot(Eigen::Vector3d(2, -1, 0.5)) + g(rng);
  const double lambda = 0.1;
  const auto solve = [lambda](const Eigen::MatrixXd& g, const Eigen::VectorXd& b) {
    return ridge_normal_solve(g, b, lambda);
  };
  const Jackknife j = block_jackknife(x, y, 10, solve);
  ASSERT_EQ(j.replicates.cols(), 10);
  EXPECT_LT((j.coef - ridge_normal_solve(x.transpose() * x, x.transpose() * y, lambda)).norm(),
            1e-10);
  for (int b = 0; b < 10; ++b) {
    std::vector<Eigen::Index> kept;
    const auto [from, to] = jackknife_block(m, 10, b);
    for (Eigen::Index i = 0; i < m; ++i)
      if (i < from || i >= to) kept.push_back(i);
    Eigen::MatrixXd xk(static_cast<Eigen::Index>(kept.size()), 3);
    Eigen::VectorXd yk(xk.rows());
    for (size_t r = 0; r < kept.size(); ++r) {
      xk.row(static_cast<Eigen::Index>(r)) = x.row(kept[r]);
      yk[static_cast<Eigen::Index>(r)] = y[kept[r]];
    }
    const Eigen::VectorXd direct = solve(xk.transpose() * xk, xk.transpose() * yk);
    EXPECT_LT((j.replicates.col(b) - direct).norm(), 1e-9) << "block " << b;
    EXPECT_GE(kept.size(), 902u);
    EXPECT_LE(kept.size(), 903u);
  }
  // The generic form gives the same replicates from a fit that reads the left-out rows.
  const Jackknife k = block_jackknife(m, 10, [&](const std::vector<bool>& out) {
    Eigen::MatrixXd g = Eigen::MatrixXd::Zero(3, 3);
    Eigen::VectorXd b = Eigen::VectorXd::Zero(3);
    for (Eigen::Index i = 0; i < m; ++i) {
      if (out[static_cast<size_t>(i)]) continue;
      g += x.row(i).transpose() * x.row(i);
      b += x.row(i).transpose() * y[i];
    }
    return solve(g, b);
  });
  EXPECT_LT((k.replicates - j.replicates).norm(), 1e-9);
  EXPECT_LT((k.sigma - j.sigma).norm(), 1e-9);
  // The covariance's diagonal is the sigmas squared.
  EXPECT_LT((j.covariance().diagonal().cwiseSqrt() - j.sigma).norm(), 1e-12);
}

TEST(BlockJackknife, MatchesTheSpreadOfFitsOverDrawsOfACorrelatedNoise) {
  // y = x b + an AR(1) noise of correlation 0.95 from row to row (about 40 rows of memory; the
  // blocks hold 200). Over 300 draws: the spread of the fitted coefficients (the reference), the
  // jackknife's std averaged, and the independent-rows formula s^2 (X'X)^-1, which takes the
  // 2000 rows for 2000 independent looks.
  const Eigen::Index m = 2000;
  const Eigen::MatrixXd x = columns(m);
  const Eigen::MatrixXd xtx_inv = (x.transpose() * x).inverse();
  std::mt19937_64 rng(11);
  std::normal_distribution<double> g(0, 1);
  const int draws = 300;
  Eigen::MatrixXd coef(3, draws);
  Eigen::Vector3d jack = Eigen::Vector3d::Zero(), naive = Eigen::Vector3d::Zero();
  for (int d = 0; d < draws; ++d) {
    Eigen::VectorXd y(m);
    double e = g(rng) / std::sqrt(1 - 0.95 * 0.95);
    for (Eigen::Index i = 0; i < m; ++i) {
      e = 0.95 * e + g(rng);
      y[i] = x.row(i).dot(Eigen::Vector3d(2, -1, 0.5)) + 0.1 * e;
    }
    const Jackknife j =
        block_jackknife(x, y, 10, [](const Eigen::MatrixXd& gm, const Eigen::VectorXd& b) {
          return ridge_normal_solve(gm, b, 1e-9);
        });
    coef.col(d) = j.coef;
    jack += j.sigma / draws;
    const double s2 = (y - x * j.coef).squaredNorm() / static_cast<double>(m - 3);
    naive += (s2 * xtx_inv.diagonal()).cwiseSqrt() / draws;
  }
  const Eigen::Vector3d mean = coef.rowwise().mean();
  const Eigen::Vector3d spread =
      ((coef.colwise() - mean).rowwise().squaredNorm() / (draws - 1)).cwiseSqrt();
  for (int c = 0; c < 3; ++c) {
    std::printf("  coefficient %d: spread over draws %.4f, jackknife %.4f, independent rows %.4f\n",
                c, spread[c], jack[c], naive[c]);
    EXPECT_GT(jack[c], 0.7 * spread[c]);
    EXPECT_LT(jack[c], 1.4 * spread[c]);
    EXPECT_LT(naive[c], 0.5 * spread[c]);  // why the jackknife: the rows are not independent
  }
}

TEST(BlockJackknife, ItsStdIsTheReplicatesSpreadTimesTheFactorOfBlocks) {
  // sigma = sqrt((B - 1) / B * sum_b (c_b - mean)^2): for replicates 2, 2.5, 1.5, 2.2 the sum of
  // squares about their mean 2.05 is 0.53, sigma = sqrt(0.75 * 0.53).
  Eigen::MatrixXd rep(1, 4);
  rep << 2.0, 2.5, 1.5, 2.2;
  EXPECT_NEAR(jackknife_sigma(rep)[0], std::sqrt(0.75 * 0.53), 1e-14);
  EXPECT_EQ(jackknife_sigma(Eigen::MatrixXd(1, 1)).size(), 1);
  EXPECT_EQ(jackknife_sigma(Eigen::MatrixXd::Constant(1, 1, 3.0))[0], 0.0);
  // Blocks cover the rows once, in order.
  Eigen::Index next = 0;
  for (int q = 0; q < 7; ++q) {
    const auto [from, to] = jackknife_block(100, 7, q);
    EXPECT_EQ(from, next);
    EXPECT_GE(to - from, 14);
    next = to;
  }
  EXPECT_EQ(next, 100);
}

}  // namespace
}  // namespace magcomp
