// magcomp tests: the per-row quadratic forms a' C a computed rows side by side equal the per-row
// form (Eigen's matrix-vector product and dot product) bit for bit, for every column count.
#include <gtest/gtest.h>

#include <cmath>
#include <random>

#include "magcomp/core/model/quadratic_form.h"

namespace magcomp {
namespace {

// A symmetric positive definite p x p matrix of mixed magnitudes, and m rows of mixed signs and
// magnitudes (so a changed summation order shows in the last bits).
void random_problem(Eigen::Index m, Eigen::Index p, unsigned seed, Eigen::MatrixXd* c,
                    Eigen::MatrixXd* a) {
  std::mt19937_64 rng(seed);
  std::normal_distribution<double> g;
  Eigen::MatrixXd l(p, p);
  for (Eigen::Index i = 0; i < p; ++i)
    for (Eigen::Index j = 0; j < p; ++j) l(i, j) = g(rng) * std::pow(10.0, (i + j) % 5 - 2);
  *c = l * l.transpose();
  a->resize(m, p);
  for (Eigen::Index i = 0; i < m; ++i)
    for (Eigen::Index j = 0; j < p; ++j) (*a)(i, j) = g(rng) * std::pow(10.0, (3 * i + j) % 7 - 3);
}

TEST(QuadraticForm, EqualsThePerRowFormBitForBitForEveryColumnCount) {
  const bool exact = Eigen::internal::packet_traits<double>::size == 2;
  long rows_checked = 0, differing_bits = 0;
  double worst = 0;
  for (Eigen::Index p = 1; p <= 27; ++p) {
    Eigen::MatrixXd c, a;
    random_problem(203, p, static_cast<unsigned>(p), &c, &a);  // 203: 6 groups of 32 and 11 rows
    Eigen::VectorXd out(a.rows());
    row_quadratic_forms(c, a, 0.75, out.data());
    for (Eigen::Index i = 0; i < a.rows(); ++i) {
      const Eigen::RowVectorXd row = a.row(i);
      const Eigen::VectorXd cr = c * row.transpose();
      const double expected = row.dot(cr) + 0.75;
      differing_bits += out[i] != expected;
      worst = std::max(worst, std::abs(out[i] - expected) / std::abs(expected));
      ++rows_checked;
    }
  }
  std::printf("  %ld rows, %ld differ in a bit, worst relative difference %.2e\n", rows_checked,
              differing_bits, worst);
  EXPECT_LT(worst, 1e-13);
  if (exact) {
    EXPECT_EQ(differing_bits, 0);
  }
}

TEST(QuadraticForm, ARowWithNanOrInfHasNoValueAndTheOthersKeepTheirs) {
  Eigen::MatrixXd c, a;
  random_problem(70, 18, 7, &c, &a);  // two groups of 32 rows and 6 more
  a(3, 17) = NAN;
  a(40, 0) = INFINITY;
  a(63, 9) = -INFINITY;
  a(69, 5) = NAN;  // in the rows past the last group
  Eigen::VectorXd out(a.rows());
  row_quadratic_forms(c, a, 1.0, out.data());
  long nan = 0;
  for (Eigen::Index i = 0; i < a.rows(); ++i) {
    if (i == 3 || i == 40 || i == 63 || i == 69) {
      EXPECT_TRUE(std::isnan(out[i])) << "row " << i;
      ++nan;
      continue;
    }
    const Eigen::RowVectorXd row = a.row(i);
    EXPECT_DOUBLE_EQ(out[i], row.dot(c * row.transpose()) + 1.0) << "row " << i;
    EXPECT_GT(out[i], 1.0);  // C is positive definite
  }
  EXPECT_EQ(nan, 4);
}

TEST(QuadraticForm, AColumnOfOnesGivesTheConstantVariance) {
  // a = (1): the form is C(0,0) + add whatever the row count.
  const Eigen::MatrixXd c = Eigen::MatrixXd::Constant(1, 1, 2.5);
  const Eigen::MatrixXd a = Eigen::MatrixXd::Ones(17, 1);
  Eigen::VectorXd out(17);
  row_quadratic_forms(c, a, 0.5, out.data());
  for (Eigen::Index i = 0; i < 17; ++i) EXPECT_EQ(out[i], 3.0);
}

}  // namespace
}  // namespace magcomp
