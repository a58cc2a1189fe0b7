// magcomp: second-order and lag terms.
#include "magcomp/core/model/terms_physical.h"

#include <array>
#include <cstdio>

namespace magcomp {

namespace {
std::vector<std::array<int, 4>> quartic_indices() {
  std::vector<std::array<int, 4>> out;
  for (int i = 0; i < 3; ++i)
    for (int j = i; j < 3; ++j)
      for (int k = j; k < 3; ++k)
        for (int l = k; l < 3; ++l) out.push_back({i, j, k, l});
  return out;
}
}  // namespace

std::vector<std::string> SecondOrderTerm::column_names() const {
  const char* axis = "xyz";
  std::vector<std::string> names;
  for (const auto& q : quartic_indices()) {
    names.push_back(std::string("second_order.") + axis[q[0]] + axis[q[1]] + axis[q[2]] +
                    axis[q[3]]);
  }
  return names;
}

void SecondOrderTerm::build(const TermInputs& in, Eigen::Ref<Eigen::MatrixXd> out) const {
  int c = 0;
  for (const auto& q : quartic_indices()) {
    out.col(c++) = (in.direction.col(q[0]).array() * in.direction.col(q[1]).array() *
                    in.direction.col(q[2]).array() * in.direction.col(q[3]).array() *
                    in.total_nT.array() / in.bt_scale_nT)
                       .matrix();
  }
}

std::string LagTerm::spec() const {
  char buf[64];
  std::snprintf(buf, sizeof(buf), "lag:%g", lag_s_);
  return buf;
}

}  // namespace magcomp
