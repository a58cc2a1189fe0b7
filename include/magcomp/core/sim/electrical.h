// magcomp simulator: aircraft electrical channels (currents in A, voltages in V) and wire fields.
#pragma once

#include <Eigen/Core>
#include <map>
#include <string>

#include "magcomp/core/sim/trajectory.h"

namespace magcomp::sim {

/// Every channel of simulated_channels(), sampled on the track: strobe pulse trains, fuel-pump
/// cycling, flap-motor bursts, radio transmit bursts, fan levels, heater thermostat, servo currents
/// following the attitude rates, bus and battery voltages drifting and sagging with the loads.
/// With `states`, also simulated_state_channels() (flap setting, engine speed, outside air
/// temperature, heater switch), from their own random stream: the others are the same.
std::map<std::string, Eigen::VectorXd> simulate_channels(const Track& track, unsigned seed,
                                                         bool states = false);

/// Magnetic field in nT at `point_m` of a straight wire segment from `a_m` to `b_m` carrying
/// 1 A from a to b (Biot-Savart, closed form for a finite segment). Frame: base_link.
Eigen::Vector3d wire_field_per_ampere_nT(const Eigen::Vector3d& a_m, const Eigen::Vector3d& b_m,
                                         const Eigen::Vector3d& point_m);

}  // namespace magcomp::sim
