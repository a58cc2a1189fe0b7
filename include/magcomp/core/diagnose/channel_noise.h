// magcomp: whether a recorded channel holds anything but its own noise: a regulated rail that
// reads a constant plus its converter's white noise records no variation an effect could follow.
#pragma once

#include <Eigen/Core>

namespace magcomp {

/// How much slower structure a channel holds than its white noise gives: the variance of its
/// means over blocks of `block_s` seconds, over the variance a white noise of the channel's own
/// sample-to-sample level would give there (that level from the median absolute difference of
/// consecutive samples, so a switch's rare steps do not raise it). Blocks with a NaN are skipped.
/// About 1 for a constant plus white noise; far above it for a switched, drifting or maneuvering
/// channel. Infinity when the channel has no sample-to-sample noise but varies from block to
/// block (a clean switch); NaN with fewer than 12 blocks or no variation at all.
double slow_to_noise_ratio(const Eigen::Ref<const Eigen::VectorXd>& x, double dt_s,
                           double block_s = 10.0);

/// The channel's variance over that of a white noise of its sample-to-sample level (as above):
/// about 1 for white noise, above it for anything correlated in time, fast or slow (a rate that
/// swings within seconds, which block means average out). NaN without finite samples or any
/// variation; infinity for a channel that varies without sample-to-sample noise.
double variance_to_noise_ratio(const Eigen::Ref<const Eigen::VectorXd>& x);

/// Limits under which a channel records its noise only (both must hold): white noise gives 1 for
/// each, within a few percent over a flight for the variance and about 15 % over 150 blocks.
constexpr double kNoiseOnlySlowRatio = 4.0;
constexpr double kNoiseOnlyVarianceRatio = 1.25;

/// A channel that records its noise only: its 10 s means and its variance are those of a white
/// noise of its sample-to-sample level. No term of it can be identified (its low-passed values are
/// a random walk of that noise, and whatever a term of it fits is that noise).
bool records_noise_only(const Eigen::Ref<const Eigen::VectorXd>& x, double dt_s);

}  // namespace magcomp
