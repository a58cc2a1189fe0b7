// magcomp: whether a trained network's gain carries over to a flight: the model scored with its
// network and with its physical terms alone, on the same samples.
#pragma once

#include <string>

#include "magcomp/core/evaluate/evaluation.h"
#include "magcomp/core/io/flight_data.h"
#include "magcomp/core/model/model.h"

namespace magcomp {

/// The network's share of a hybrid's result on one flight.
struct NetworkGain {
  Evaluation physics;         ///< the model without its neural stage (its terms alone)
  double gain_std = 0.0;      ///< 1 - std with the network / std of the physics (>0: it helps)
  bool carries_over = false;  ///< the network lowers the std by at least kNetworkGainResolution
  bool worse = false;         ///< the network raises the std (by more than the resolution)
  std::string verdict;        ///< one line saying which, with both figures
};

/// A change in std below this share (1 %) is no gain nor loss.
constexpr double kNetworkGainResolution = 0.01;

/// The verdict on `flight` from the two scores already made on the same samples: the physical
/// terms alone and the whole model with its network (their std_nT, nT).
NetworkGain network_gain(const Evaluation& physics, const Evaluation& with_network,
                         const std::string& flight);

/// Scores `model`'s physical terms alone against `truth` on `data` and compares them with
/// `with_network` (evaluate_model of the whole model there). Throws magcomp::Error when the model
/// has no trained neural stage.
NetworkGain network_gain(const Model& model, const FlightData& data, const std::string& truth,
                         const Evaluation& with_network);

}  // namespace magcomp
