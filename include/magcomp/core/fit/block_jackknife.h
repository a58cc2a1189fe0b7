// magcomp: the delete-a-block jackknife of a fit's coefficients: how much they rest on a few
// stretches of the rows that size them.
#pragma once

#include <Eigen/Core>
#include <functional>
#include <utility>
#include <vector>

namespace magcomp {

/// A fit repeated with each of B contiguous blocks of its rows left out in turn.
struct Jackknife {
  Eigen::VectorXd coef;        ///< the fit on every row, k (the coefficients' units)
  Eigen::MatrixXd replicates;  ///< k x B: the fit without block b, column b
  Eigen::VectorXd sigma;       ///< each coefficient's jackknife std, k (the coefficients' units)
  /// The coefficients' jackknife covariance, k x k: (B - 1) / B times the replicates' spread.
  Eigen::MatrixXd covariance() const;
};

/// The jackknife std of each coefficient from its B replicates (k x B):
/// sqrt((B - 1) / B * sum_b (c_b - mean_b c)^2). Zeros when B < 2.
Eigen::VectorXd jackknife_sigma(const Eigen::MatrixXd& replicates);

/// Block q of `blocks` over `rows` rows: rows [rows * q / blocks, rows * (q + 1) / blocks), in
/// the rows' order (integer division: contiguous blocks of nearly equal size).
std::pair<Eigen::Index, Eigen::Index> jackknife_block(Eigen::Index rows, int blocks, int q);

/// A fit from its normal equations: coefficients (k) from G = X'X (k x k) and b = X'y (k).
using NormalSolve = std::function<Eigen::VectorXd(const Eigen::MatrixXd&, const Eigen::VectorXd&)>;

/// The fit of y (M) on x (M x k) by `solve`, on every row and with each of `blocks` blocks of
/// rows (jackknife_block) left out: each block's normal equations formed once and taken from
/// the whole's. blocks >= 2.
Jackknife block_jackknife(const Eigen::MatrixXd& x, const Eigen::VectorXd& y, int blocks,
                          const NormalSolve& solve);

/// The same for a fit that reads its rows itself: `fit(left_out)` with `left_out` (`rows`
/// flags) all false, then flagging each block in turn; `fit` returns the k coefficients.
Jackknife block_jackknife(Eigen::Index rows, int blocks,
                          const std::function<Eigen::VectorXd(const std::vector<bool>&)>& fit);

}  // namespace magcomp
