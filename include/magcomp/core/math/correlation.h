// magcomp: how closely two sampled series move together: Pearson's r, and the ranks that make it
// Spearman's rho.
#pragma once

#include <Eigen/Core>

namespace magcomp {

/// The correlation above which two recorded channels are look-alikes of one another (|r|,
/// Pearson): a flight cannot tell an effect of one from an effect of the other. The network's
/// attribution and the diagnosis loop both use it.
constexpr double kLookAlikeCorrelation = 0.95;

/// Pearson's correlation of `a` and `b` (same length, any unit each), dimensionless; 0 when
/// either is constant.
double pearson(const Eigen::Ref<const Eigen::VectorXd>& a,
               const Eigen::Ref<const Eigen::VectorXd>& b);

/// pearson() of `a` and `b` (same length) over the rows where both are finite; NaN with fewer
/// than `min_rows` such rows.
double pearson_where_finite(const Eigen::Ref<const Eigen::VectorXd>& a,
                            const Eigen::Ref<const Eigen::VectorXd>& b, Eigen::Index min_rows);

/// The ranks of `x` (0 for the smallest), ties given their average rank: Spearman's rho of two
/// series is pearson() of their ranks.
Eigen::VectorXd ranks(const Eigen::Ref<const Eigen::VectorXd>& x);

}  // namespace magcomp
