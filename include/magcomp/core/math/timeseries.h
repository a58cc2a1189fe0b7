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

/// The columns of `a` (uniformly sampled) as a sensor that reads them `lag_samples` late, once
/// realigned, sees them: each column delayed by the lag and advanced back by it, both by the
/// cubic interpolation of shift_samples (ends held). A fractional shift of a sampled record cannot
/// be undone, so a lagging scalar realigned by the lag carries this smoothing of everything it
/// measured; a model whose columns carry it too fits the realigned scalar exactly. The identity
/// for a whole number of samples.
void lag_round_trip(Eigen::Ref<Eigen::MatrixXd> a, double lag_samples);
/// Rows on each side of a row that lag_round_trip() reads: 0 for a whole number of samples, 3
/// otherwise (the delay's and the advance's interpolation windows overlap but for those).
int lag_round_trip_reach(double lag_samples);
/// Rows a slice of a column needs beyond each row it keeps so that lag_round_trip() of the slice
/// gives those rows the numbers of the whole column's: 0 for a whole number of samples,
/// ceil(|lag_samples|) + 3 otherwise (the delayed intermediate is read that far past the row,
/// and the slice's held ends must not reach it).
int lag_round_trip_slice_margin(double lag_samples);

/// The rate of x (units per s), samples dt_s apart, by central differences (one-sided at the
/// ends). With `wrap_angle`, x is an angle in rad and each difference is wrapped to (-pi, pi].
Eigen::VectorXd central_rate(const Eigen::Ref<const Eigen::VectorXd>& x, double dt_s,
                             bool wrap_angle = false);

/// x (uniformly sampled, its unit) as a centred moving average over 2 half + 1 samples of its
/// finite values (fewer at the ends); NaN where the window holds none.
Eigen::VectorXd moving_average(const Eigen::Ref<const Eigen::VectorXd>& x, Eigen::Index half);

}  // namespace magcomp
