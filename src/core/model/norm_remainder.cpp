// magcomp: the exact norm's remainder from TL's coefficients (see norm_remainder.h).
#include "magcomp/core/model/norm_remainder.h"

#include <Eigen/Geometry>
#include <cmath>

namespace magcomp {

namespace {
int axis_of(char c) { return c == 'x' ? 0 : c == 'y' ? 1 : c == 'z' ? 2 : -1; }
}  // namespace

Eigen::MatrixX3d tl_vector_field_nT(const TermInputs& in,
                                    const std::vector<std::string>& column_names,
                                    const Eigen::VectorXd& coefficients) {
  Eigen::Vector3d permanent_nT = Eigen::Vector3d::Zero();
  Eigen::Matrix3d induced = Eigen::Matrix3d::Zero(), eddy = Eigen::Matrix3d::Zero();
  const size_t n = std::min(column_names.size(), static_cast<size_t>(coefficients.size()));
  for (size_t k = 0; k < n; ++k) {
    const std::string& name = column_names[k];
    const double c = coefficients[static_cast<Eigen::Index>(k)];
    const auto dot = name.find('.');
    if (dot == std::string::npos || !std::isfinite(c)) continue;
    const std::string family = name.substr(0, dot), axes = name.substr(dot + 1);
    if (family == "permanent" && axes.size() == 1 && axis_of(axes[0]) >= 0) {
      permanent_nT[axis_of(axes[0])] = c;
      continue;
    }
    if (axes.size() != 2 || axis_of(axes[0]) < 0 || axis_of(axes[1]) < 0) continue;
    const int i = axis_of(axes[0]), j = axis_of(axes[1]);
    if (family.rfind("induced", 0) == 0 && family.find(':') == std::string::npos) {
      // Column B̂i·Bj: B̂'AB = Σ A_ij B̂i Bj, the off-diagonal pair written once.
      if (i == j) {
        induced(i, i) = c;
      } else {
        induced(i, j) = induced(j, i) = 0.5 * c;
      }
    } else if (family.rfind("eddy", 0) == 0 && family.find(':') == std::string::npos) {
      eddy(i, j) = c;  // column B̂i·dBj
    }
  }
  Eigen::MatrixX3d v =
      (in.field_nT * induced.transpose() + in.delta_nT * eddy.transpose()) / in.bt_scale_nT;
  v.rowwise() += permanent_nT.transpose();
  return v;
}

Eigen::VectorXd norm_remainder_nT(const TermInputs& in,
                                  const std::vector<std::string>& column_names,
                                  const Eigen::VectorXd& coefficients) {
  const Eigen::MatrixX3d v = tl_vector_field_nT(in, column_names, coefficients);
  Eigen::VectorXd out(in.field_nT.rows());
  for (Eigen::Index r = 0; r < out.size(); ++r) {
    const Eigen::Vector3d b = in.field_nT.row(r).transpose(), a = v.row(r).transpose();
    const double b_norm = b.norm(), ba_norm = (b + a).norm();
    // |B + v| - |B| without cancellation, then the first-order part B̂·v removed.
    const double change = (2.0 * b.dot(a) + a.squaredNorm()) / (ba_norm + b_norm);
    out[r] = change - b.dot(a) / b_norm;
  }
  return out;
}

}  // namespace magcomp
