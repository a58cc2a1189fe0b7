// magcomp: Tolles-Lawson columns.
#include "magcomp/core/model/terms_tl.h"

namespace magcomp {
namespace {
const char* kAxis[3] = {"x", "y", "z"};
}

std::vector<std::string> PermanentTerm::column_names() const {
  return {"permanent.x", "permanent.y", "permanent.z"};
}

void PermanentTerm::build(const TermInputs& in, Eigen::Ref<Eigen::MatrixXd> out) const {
  out = in.direction;
}

namespace {
// (i, j) index pairs of the induced family, MagNav.jl order.
std::vector<std::pair<int, int>> induced_pairs(int columns) {
  if (columns == 3) return {{0, 0}, {1, 1}, {2, 2}};
  std::vector<std::pair<int, int>> p = {{0, 0}, {0, 1}, {0, 2}, {1, 1}, {1, 2}, {2, 2}};
  if (columns == 5) p.pop_back();
  return p;
}
std::vector<std::pair<int, int>> eddy_pairs(int columns) {
  if (columns == 3) return {{0, 0}, {1, 1}, {2, 2}};
  std::vector<std::pair<int, int>> p;
  for (int i = 0; i < 3; ++i)
    for (int j = 0; j < 3; ++j) p.emplace_back(i, j);
  if (columns == 8) p.pop_back();
  return p;
}
}  // namespace

std::string InducedTerm::spec() const {
  return columns_ == 6 ? "induced" : "induced" + std::to_string(columns_);
}

std::vector<std::string> InducedTerm::column_names() const {
  std::vector<std::string> names;
  for (auto [i, j] : induced_pairs(columns_)) names.push_back(spec() + "." + kAxis[i] + kAxis[j]);
  return names;
}

void InducedTerm::build(const TermInputs& in, Eigen::Ref<Eigen::MatrixXd> out) const {
  int c = 0;
  for (auto [i, j] : induced_pairs(columns_)) {
    out.col(c++) = in.direction.col(i).cwiseProduct(in.field_nT.col(j)) / in.bt_scale_nT;
  }
}

std::string EddyTerm::spec() const {
  return columns_ == 9 ? "eddy" : "eddy" + std::to_string(columns_);
}

std::vector<std::string> EddyTerm::column_names() const {
  std::vector<std::string> names;
  for (auto [i, j] : eddy_pairs(columns_)) names.push_back(spec() + "." + kAxis[i] + kAxis[j]);
  return names;
}

void EddyTerm::build(const TermInputs& in, Eigen::Ref<Eigen::MatrixXd> out) const {
  int c = 0;
  for (auto [i, j] : eddy_pairs(columns_)) {
    out.col(c++) = in.direction.col(i).cwiseProduct(in.delta_nT.col(j)) / in.bt_scale_nT;
  }
}

std::vector<std::string> FdmTerm::column_names() const { return {"fdm.x", "fdm.y", "fdm.z"}; }

void FdmTerm::build(const TermInputs& in, Eigen::Ref<Eigen::MatrixXd> out) const {
  out = in.delta_nT;
}

void BiasTerm::build(const TermInputs&, Eigen::Ref<Eigen::MatrixXd> out) const { out.setOnes(); }

}  // namespace magcomp
