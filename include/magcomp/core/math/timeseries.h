// magcomp: small time-series helpers shared by the model and the simulator.
#pragma once

#include <Eigen/Core>

namespace magcomp {

/// Catmull-Rom cubic interpolation of uniformly sampled x at fractional sample index u; indices
/// beyond either end take the end value.
double cubic_at(const Eigen::Ref<const Eigen::VectorXd>& x, double u);

/// x delayed (shift_samples > 0: y[i] = x(i - shift)) or advanced (< 0), by cubic interpolation
/// (exact for whole samples). Samples that would need data beyond either end are NaN, or the end
/// value when `hold_ends` is true.
Eigen::VectorXd shift_samples(const Eigen::Ref<const Eigen::VectorXd>& x, double shift_samples,
                              bool hold_ends = false);

/// The rate of x (units per s), samples dt_s apart, by central differences (one-sided at the
/// ends). With `wrap_angle`, x is an angle in rad and each difference is wrapped to (-pi, pi].
Eigen::VectorXd central_rate(const Eigen::Ref<const Eigen::VectorXd>& x, double dt_s,
                             bool wrap_angle = false);

}  // namespace magcomp
