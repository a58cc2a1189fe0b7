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

/// The integrated correlation time of `x` (uniformly sampled `dt_s` apart, any unit), s: the
/// integral over the lag of its autocorrelation, from 0 to the first lag where that falls to 0,
/// its non-finite samples left out. A series T s long holds about T / (2 tau) independent values;
/// a first-order low-pass of white noise with time constant tau has tau, a sine of period P has
/// P / (2 pi). The autocorrelation is read at lags spaced by a quarter of an octave (from one
/// sample to half the series) and integrated piecewise linearly, up to half the series when it
/// never falls to 0. 0 for a constant or empty series.
double correlation_time_s(const Eigen::Ref<const Eigen::VectorXd>& x, double dt_s);

}  // namespace magcomp
