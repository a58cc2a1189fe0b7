// magcomp: the slow stage of a band-pass fit (Model::slow_terms).
#pragma once

#include <Eigen/Core>
#include <utility>
#include <vector>

namespace magcomp {

/// The slow stage of a band-pass fit (Model::slow_terms): the coefficients of columns too slow
/// for the band-pass, fitted on the calibration rows `runs` (first, last) to `target` (N, nT: the
/// scalar minus the reference minus the band-pass correction), unfiltered, each run's mean
/// removed, with the fast columns' span removed from both (`fast`, N x p: the band-pass
/// columns, whose low-frequency misfit would otherwise leak into the slow coefficients; their
/// own coefficients stay as the band-pass fitted them). Least squares with ridge `lambda`. Rows
/// where the target or a fast column is not finite are skipped, and so are the rows flagged in
/// `left_out` (N, optional: a jackknife's block; each run's mean is then that of its other rows).
class SlowStage {
 public:
  SlowStage(const Eigen::MatrixXd& fast, const Eigen::VectorXd& target,
            const std::vector<std::pair<Eigen::Index, Eigen::Index>>& runs, double lambda,
            const std::vector<bool>* left_out = nullptr);
  /// The coefficients of the columns `s` (N x k, per unit of column; a non-finite value counts as
  /// its run's mean); `rss` (nT², optional) gets the residual sum of squares.
  Eigen::VectorXd fit(const Eigen::MatrixXd& s, double* rss = nullptr) const;
  /// The residual sum of squares with no slow column, nT².
  double base_rss() const { return e_.squaredNorm(); }
  /// The rows used.
  Eigen::Index rows() const { return e_.size(); }

 private:
  Eigen::MatrixXd centred(const Eigen::MatrixXd& x) const;  // the used rows, run means removed
  std::vector<Eigen::Index> rows_;                          // the used rows of the flight
  std::vector<std::pair<size_t, size_t>> segments_;         // [begin, end) in rows_, per run
  Eigen::MatrixXd d_;                                       // the fast columns, centred
  Eigen::MatrixXd ginv_;                                    // (d_'d_ + lambda)^-1
  Eigen::VectorXd w_;                                       // ginv_ d_' e_
  Eigen::VectorXd e_;                                       // the target, centred, d_ removed
  double lambda_ = 0;
};

}  // namespace magcomp
