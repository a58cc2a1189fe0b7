// magcomp: the per-sample quadratic form a' C a of a design matrix's rows (the compensation's
// variance from the coefficients' covariance), many rows at a time.
#pragma once

#include <Eigen/Core>

namespace magcomp {

/// out[i] = a.row(i) C a.row(i)' + add for every row i of `a` (m x p, nT per column unit; C p x p,
/// nT² per (column unit)²; add and out in nT²), NaN for a row holding NaN or Inf. The numbers equal
/// the per-row form `row.dot(C * row.transpose()) + add` bit for bit: each row's sums are taken
/// in that form's order (the product C a summed over columns in order, then the dot product's
/// partial sums as Eigen forms them with two-double packets), only several rows share each
/// instruction. Builds whose Eigen packets are not two doubles, or that fuse multiply-adds, use
/// the per-row form itself.
void row_quadratic_forms(const Eigen::MatrixXd& c, const Eigen::Ref<const Eigen::MatrixXd>& a,
                         double add, double* out);

/// The per-row form itself, for one row: row C row' + add (nT²), NaN for a row holding NaN or
/// Inf; `buffer` receives C row' (a per-sample caller reuses it).
double row_quadratic_form(const Eigen::MatrixXd& c, const Eigen::Ref<const Eigen::RowVectorXd>& row,
                          double add, Eigen::VectorXd* buffer);

}  // namespace magcomp
