// magcomp simulator: hidden effects drawn at random, a test set no catalogue can be tuned to:
// random sources (any current, voltage or INS channel), transform chains (low-pass, power,
// derivative), products of two channels, static switches, hysteresis, flexing structures, lags,
// and ripples whose phase no channel records; one to three at once.
#pragma once

#include <string>
#include <vector>

#include "magcomp/core/geo/igrf.h"
#include "magcomp/core/sim/scenario.h"

namespace magcomp::sim {

/// `count` effects (>= 1) drawn from `seed` for the flight of `base` (on mag_5_uc): kinds and
/// parameters at random; each effect's gain set so its rms contribution on that flight is drawn
/// log-uniformly in [rms_min_nT, rms_max_nT] (a pilot simulation measures it; a lag keeps its
/// drawn delay); thresholds and play widths from the channel's own range on that flight. An
/// effect another flight of the aircraft (scenario seed + 7919) shows more than 50 times its
/// drawn rms is drawn again: a flight that barely moves an effect's channel cannot size it. The
/// same effects on another flight of the same aircraft (another `seed` of the scenario) make
/// its next flight. Throws Error when 20 draws leave such an effect.
std::vector<HiddenEffect> random_effects(const Scenario& base, unsigned seed, int count,
                                         const Igrf& igrf, double rms_min_nT = 0.3,
                                         double rms_max_nT = 3.0);

/// Whether the term language can express or approximate the effect (a ripple whose phase no
/// channel records cannot be predicted in sign).
bool predictable(const HiddenEffect& e);

/// One line: kind and parameters ("thermal cur_heat^2 lp 240 s, 1.2 nT rms").
std::string describe(const HiddenEffect& e);

}  // namespace magcomp::sim
