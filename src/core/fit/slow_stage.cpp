// magcomp: the slow stage of a band-pass fit: columns too slow for the band, fitted against a
// reference with the band-pass columns' span removed.
#include "magcomp/core/fit/slow_stage.h"

#include <Eigen/Dense>
#include <algorithm>
#include <cmath>

#include "magcomp/core/math/tall_products.h"

namespace magcomp {

SlowStage::SlowStage(const Eigen::MatrixXd& fast, const Eigen::VectorXd& target,
                     const std::vector<std::pair<Eigen::Index, Eigen::Index>>& runs, double lambda,
                     const std::vector<bool>* left_out)
    : lambda_(lambda) {
  for (const auto& [first, last] : runs) {
    const size_t begin = rows_.size();
    for (Eigen::Index i = first; i <= last; ++i) {
      if (left_out && (*left_out)[static_cast<size_t>(i)]) continue;
      if (std::isfinite(target[i]) && fast.row(i).allFinite()) rows_.push_back(i);
    }
    if (rows_.size() - begin < 2) {
      rows_.resize(begin);
    } else {
      segments_.emplace_back(begin, rows_.size());
    }
  }
  d_ = centred(fast);
  Eigen::MatrixXd g = d_.transpose() * d_;
  g.diagonal().array() += lambda_;
  const Eigen::Index p = d_.cols();
  ginv_ = g.ldlt().solve(Eigen::MatrixXd::Identity(p, p));
  e_ = centred(target);
  if (p > 0) e_ -= d_ * (ginv_ * (d_.transpose() * e_));
  w_ = ginv_ * (d_.transpose() * e_);
}

Eigen::MatrixXd SlowStage::centred(const Eigen::MatrixXd& x) const {
  Eigen::MatrixXd out(static_cast<Eigen::Index>(rows_.size()), x.cols());
  for (const auto& [begin, end] : segments_) {
    for (Eigen::Index c = 0; c < x.cols(); ++c) {
      double sum = 0, n = 0;
      for (size_t k = begin; k < end; ++k) {
        const double v = x(rows_[k], c);
        if (std::isfinite(v)) {
          sum += v;
          n += 1;
        }
      }
      const double mean = n > 0 ? sum / n : 0.0;
      for (size_t k = begin; k < end; ++k) {
        const double v = x(rows_[k], c);
        out(static_cast<Eigen::Index>(k), c) = std::isfinite(v) ? v - mean : 0.0;
      }
    }
  }
  return out;
}

Eigen::VectorXd SlowStage::fit(const Eigen::MatrixXd& s, double* rss) const {
  // The normal equations of the columns with the fast columns' span removed, from products
  // with the centred columns (no residualised copy): S~'S~ = S'S - (D'S)' G^-1 (D'S), and
  // S~'e = S'e - (D'S)' G^-1 D'e with e already residualised.
  const Eigen::MatrixXd sc = centred(s);
  Eigen::MatrixXd g = gram(sc);
  Eigen::VectorXd aty = sc.transpose() * e_;
  if (d_.cols() > 0) {
    const Eigen::MatrixXd dts = transpose_product(d_, sc);
    g -= dts.transpose() * (ginv_ * dts);
    aty -= dts.transpose() * w_;
  }
  Eigen::MatrixXd ridged = g;
  ridged.diagonal().array() += lambda_;
  const Eigen::VectorXd c = ridged.ldlt().solve(aty);
  if (rss) *rss = std::max(0.0, e_.squaredNorm() - 2.0 * c.dot(aty) + c.dot(g * c));
  return c;
}

}  // namespace magcomp
