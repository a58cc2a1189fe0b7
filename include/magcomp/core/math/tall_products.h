// magcomp: products of tall matrices (thousands of rows) as the fits and the term searches form
// them for every candidate they score: A'B for a narrow B, and Gram matrices A'A.
#pragma once

#include <Eigen/Core>

namespace magcomp {

/// a'b (a.cols() × b.cols(), the product of the two units) for a and b of the same rows: one
/// matrix-vector product per column of b while b has few columns (a general matrix product
/// copies all of a into its packed blocks on each call: twice the time for three columns of
/// 12,000 rows), the matrix product otherwise.
Eigen::MatrixXd transpose_product(const Eigen::Ref<const Eigen::MatrixXd>& a,
                                  const Eigen::Ref<const Eigen::MatrixXd>& b);

/// a'a (a.cols() × a.cols(), a's unit squared): the columns' dot products while a has few
/// columns, a symmetric rank update (half a general product's work) otherwise.
Eigen::MatrixXd gram(const Eigen::Ref<const Eigen::MatrixXd>& a);

}  // namespace magcomp
