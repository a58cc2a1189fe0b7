// The tall-matrix products against Faulhaber's sums: for columns x^p on x_i = i / n, every entry
// of A'B and A'A is the closed form of a sum of powers, on the few-column path (matrix-vector and
// dot products) and the wide one (matrix product, symmetric rank update) alike.
#include <gtest/gtest.h>

#include <cmath>

#include "magcomp/core/math/tall_products.h"

namespace magcomp {
namespace {

constexpr Eigen::Index kRows = 5000;

// sum_{i=0}^{n-1} (i/n)^k for k = 0..6 (Faulhaber), divided through by n^k.
double power_sum(int k) {
  const double n = static_cast<double>(kRows), m = n - 1;
  double s = 0;
  switch (k) {
    case 0:
      s = n;
      break;
    case 1:
      s = m * n / 2;
      break;
    case 2:
      s = m * n * (2 * m + 1) / 6;
      break;
    case 3:
      s = std::pow(m * n / 2, 2);
      break;
    case 4:
      s = m * n * (2 * m + 1) * (3 * m * m + 3 * m - 1) / 30;
      break;
    case 5:
      s = m * m * n * n * (2 * m * m + 2 * m - 1) / 12;
      break;
    case 6:
      s = m * n * (2 * m + 1) * (3 * std::pow(m, 4) + 6 * std::pow(m, 3) - 3 * m + 1) / 42;
      break;
    default:
      ADD_FAILURE() << "power " << k;
  }
  return s / std::pow(n, k);
}

// Columns x^powers[j] on x_i = i / n.
Eigen::MatrixXd powers_of_x(const std::vector<int>& powers) {
  Eigen::MatrixXd a(kRows, static_cast<Eigen::Index>(powers.size()));
  for (Eigen::Index i = 0; i < kRows; ++i)
    for (size_t j = 0; j < powers.size(); ++j)
      a(i, static_cast<Eigen::Index>(j)) = std::pow(static_cast<double>(i) / kRows, powers[j]);
  return a;
}

TEST(TallProducts, EveryEntryIsItsSumOfPowersOnTheNarrowAndTheWidePath) {
  const std::vector<int> base = {0, 1, 2, 3};
  for (const std::vector<int>& cand :
       {std::vector<int>{1, 2, 3}, std::vector<int>{0, 1, 2, 3, 0, 1, 2, 3, 1, 2}}) {
    const Eigen::MatrixXd a = powers_of_x(base), b = powers_of_x(cand);
    const Eigen::MatrixXd ab = transpose_product(a, b);
    const Eigen::MatrixXd bb = gram(b);
    ASSERT_EQ(ab.rows(), 4);
    ASSERT_EQ(ab.cols(), b.cols());
    ASSERT_EQ(bb.rows(), b.cols());
    for (Eigen::Index i = 0; i < a.cols(); ++i)
      for (Eigen::Index j = 0; j < b.cols(); ++j) {
        const double want = power_sum(base[i] + cand[j]);
        EXPECT_NEAR(ab(i, j), want, 1e-12 * want) << i << ", " << j << " of " << b.cols();
      }
    for (Eigen::Index i = 0; i < b.cols(); ++i)
      for (Eigen::Index j = 0; j < b.cols(); ++j) {
        const double want = power_sum(cand[i] + cand[j]);
        EXPECT_NEAR(bb(i, j), want, 1e-12 * want) << i << ", " << j << " of " << b.cols();
        EXPECT_EQ(bb(i, j), bb(j, i));  // symmetric to the bit
      }
  }
}

}  // namespace
}  // namespace magcomp
