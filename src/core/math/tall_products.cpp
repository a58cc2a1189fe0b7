// magcomp: products of tall matrices.
#include "magcomp/core/math/tall_products.h"

#include <Eigen/Dense>

namespace magcomp {
namespace {
// Up to this many columns, matrix-vector products or dot products (scripts/bench_diagnose).
constexpr Eigen::Index kNarrowColumns = 8;
}  // namespace

Eigen::MatrixXd transpose_product(const Eigen::Ref<const Eigen::MatrixXd>& a,
                                  const Eigen::Ref<const Eigen::MatrixXd>& b) {
  if (b.cols() > kNarrowColumns) return a.transpose() * b;
  Eigen::MatrixXd out(a.cols(), b.cols());
  for (Eigen::Index j = 0; j < b.cols(); ++j) out.col(j).noalias() = a.transpose() * b.col(j);
  return out;
}

Eigen::MatrixXd gram(const Eigen::Ref<const Eigen::MatrixXd>& a) {
  Eigen::MatrixXd out = Eigen::MatrixXd::Zero(a.cols(), a.cols());
  if (a.cols() > kNarrowColumns) {
    out.selfadjointView<Eigen::Lower>().rankUpdate(a.transpose());
    return out.selfadjointView<Eigen::Lower>();
  }
  for (Eigen::Index i = 0; i < a.cols(); ++i)
    for (Eigen::Index j = 0; j <= i; ++j) out(i, j) = out(j, i) = a.col(i).dot(a.col(j));
  return out;
}

}  // namespace magcomp
