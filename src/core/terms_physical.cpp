// magcomp: current and lag terms.
#include "magcomp/core/terms_physical.h"

#include <array>
#include <cstdio>

namespace magcomp {

std::string CurrentTerm::effect() const {
  if (attitude_) {
    return "field ∝ attitude rate " + channel_ + " (vibration, control surfaces), projected";
  }
  return rate_
             ? "inductive pick-up ∝ dI/dt of " + channel_ + ", projected on the field direction"
             : "field of a wire carrying " + channel_ + " (∝ I), projected on the field direction";
}

std::vector<std::string> CurrentTerm::column_names() const {
  const std::string s = spec();
  return {s + ".x", s + ".y", s + ".z"};
}

void CurrentTerm::build(const TermInputs& in, Eigen::Ref<Eigen::MatrixXd> out) const {
  Eigen::VectorXd signal = in.data->column(channel_);
  if (rate_) signal = central_difference(signal) / in.dt_s;
  for (int c = 0; c < 3; ++c) out.col(c) = in.direction.col(c).cwiseProduct(signal);
}

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
