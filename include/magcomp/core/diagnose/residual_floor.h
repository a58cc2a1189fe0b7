// magcomp: what a residual is made of when no model term explains it: its white-noise floor, read
// from its own spectrum (not from the model), and whether its power follows a recorded channel
// even where its sign cannot be predicted.
#pragma once

#include <Eigen/Core>
#include <string>
#include <utility>
#include <vector>

#include "magcomp/core/io/channel_kinds.h"

namespace magcomp {

/// The noise floor of a held-out residual and the channel its local power follows.
struct ResidualFloor {
  bool computed = false;
  double residual_std_nT = 0.0;  ///< std of the held-out residual (each unit's mean removed), nT
  double floor_nT = 0.0;         ///< white-noise std: the spectrum's median level above band_lo_hz
  double band_lo_hz = 0.0;       ///< the floor is read between band_lo_hz and the Nyquist frequency
  int segments = 0;              ///< spectral segments averaged
  /// The channel whose value best ranks the residual's local variance (10 s windows), with the
  /// Spearman correlation; empty when no channel's correlation is significant.
  std::string amplitude_channel;
  double amplitude_correlation = 0.0;
  int amplitude_windows = 0;  ///< windows the correlation was taken over
  /// The channel whose mean over each spectral segment best ranks that segment's level above
  /// band_lo_hz (Spearman), when the correlation is significant over every channel tested (4
  /// sigma of the half-overlapping segments' effective count, and at least 0.3): the floor then
  /// follows a state or a motion of the aircraft, so it is an effect (a relay chattering on its
  /// channel's noise, a vibration), not the sensor's white noise. Empty otherwise.
  std::string floor_channel;
  double floor_correlation = 0.0;
};

/// Inputs: the residual (N, NaN where not held out), each sample's held-out unit (-1: not held
/// out; a unit is contiguous in time), the sample rate (Hz) and the channels to test for the
/// residual's power (name, values over the whole flight). The floor is the median, over the
/// frequencies above `band_lo_fraction` x Nyquist, of the residual's averaged periodogram
/// (Hann-windowed, detrended 256-sample segments, half overlapping), turned into the std of a
/// white noise of that level: narrow lines (a ripple) and the aircraft's band below do not move it.
ResidualFloor residual_floor(
    const Eigen::VectorXd& residual, const std::vector<int>& unit, double sample_rate_hz,
    const std::vector<std::pair<std::string, Eigen::Map<const Eigen::VectorXd>>>& channels,
    double band_lo_fraction = 0.5);

}  // namespace magcomp
