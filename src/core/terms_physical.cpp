// magcomp: current and lag terms.
#include "magcomp/core/terms_physical.h"

#include <cstdio>

namespace magcomp {

std::string CurrentTerm::effect() const {
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

std::string LagTerm::spec() const {
  char buf[64];
  std::snprintf(buf, sizeof(buf), "lag:%g", lag_s_);
  return buf;
}

}  // namespace magcomp
