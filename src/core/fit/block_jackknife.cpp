// magcomp: the delete-a-block jackknife of a fit's coefficients.
#include "magcomp/core/fit/block_jackknife.h"

#include <cmath>

#include "magcomp/core/error.h"
#include "magcomp/core/math/tall_products.h"

namespace magcomp {

Eigen::MatrixXd Jackknife::covariance() const {
  const Eigen::Index b = replicates.cols();
  if (b < 2) return Eigen::MatrixXd::Zero(replicates.rows(), replicates.rows());
  const Eigen::MatrixXd centred = replicates.colwise() - replicates.rowwise().mean();
  return (static_cast<double>(b - 1) / static_cast<double>(b)) * centred * centred.transpose();
}

Eigen::VectorXd jackknife_sigma(const Eigen::MatrixXd& replicates) {
  const Eigen::Index b = replicates.cols();
  if (b < 2) return Eigen::VectorXd::Zero(replicates.rows());
  const Eigen::VectorXd mean = replicates.rowwise().mean();
  const Eigen::VectorXd ss = (replicates.colwise() - mean).rowwise().squaredNorm();
  return (ss * (static_cast<double>(b - 1) / static_cast<double>(b))).cwiseSqrt();
}

std::pair<Eigen::Index, Eigen::Index> jackknife_block(Eigen::Index rows, int blocks, int q) {
  return {rows * q / blocks, rows * (q + 1) / blocks};
}

Jackknife block_jackknife(const Eigen::MatrixXd& x, const Eigen::VectorXd& y, int blocks,
                          const NormalSolve& solve) {
  if (blocks < 2) throw Error("jackknife: at least 2 blocks are needed");
  const Eigen::Index m = x.rows(), k = x.cols();
  std::vector<Eigen::MatrixXd> g(static_cast<size_t>(blocks));
  std::vector<Eigen::VectorXd> b(static_cast<size_t>(blocks));
  Eigen::MatrixXd g_all = Eigen::MatrixXd::Zero(k, k);
  Eigen::VectorXd b_all = Eigen::VectorXd::Zero(k);
  for (int q = 0; q < blocks; ++q) {
    const auto [from, to] = jackknife_block(m, blocks, q);
    const auto part = x.middleRows(from, to - from);
    g[static_cast<size_t>(q)] = gram(part);
    b[static_cast<size_t>(q)] = part.transpose() * y.segment(from, to - from);
    g_all += g[static_cast<size_t>(q)];
    b_all += b[static_cast<size_t>(q)];
  }
  Jackknife j;
  j.coef = solve(g_all, b_all);
  j.replicates.resize(k, blocks);
  for (int q = 0; q < blocks; ++q)
    j.replicates.col(q) =
        solve(g_all - g[static_cast<size_t>(q)], b_all - b[static_cast<size_t>(q)]);
  j.sigma = jackknife_sigma(j.replicates);
  return j;
}

Jackknife block_jackknife(Eigen::Index rows, int blocks,
                          const std::function<Eigen::VectorXd(const std::vector<bool>&)>& fit) {
  if (blocks < 2) throw Error("jackknife: at least 2 blocks are needed");
  Jackknife j;
  std::vector<bool> left_out(static_cast<size_t>(rows), false);
  j.coef = fit(left_out);
  j.replicates.resize(j.coef.size(), blocks);
  for (int q = 0; q < blocks; ++q) {
    const auto [from, to] = jackknife_block(rows, blocks, q);
    for (Eigen::Index r = 0; r < rows; ++r) left_out[static_cast<size_t>(r)] = r >= from && r < to;
    j.replicates.col(q) = fit(left_out);
  }
  j.sigma = jackknife_sigma(j.replicates);
  return j;
}

}  // namespace magcomp
