// magcomp: how closely two sampled series move together: Pearson's r, and the ranks that make it
// Spearman's rho.
#pragma once

#include <Eigen/Core>

namespace magcomp {

/// Pearson's correlation of `a` and `b` (same length, any unit each), dimensionless; 0 when
/// either is constant.
double pearson(const Eigen::Ref<const Eigen::VectorXd>& a,
               const Eigen::Ref<const Eigen::VectorXd>& b);

/// The ranks of `x` (0 for the smallest), ties given their average rank: Spearman's rho of two
/// series is pearson() of their ranks.
Eigen::VectorXd ranks(const Eigen::Ref<const Eigen::VectorXd>& x);

}  // namespace magcomp
