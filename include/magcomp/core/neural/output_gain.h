// magcomp: the network's share of a hybrid model's correction, fitted on flights the network was
// not trained on, so that the hybrid is no worse there than its physics part.
#pragma once

#include <memory>
#include <vector>

#include "magcomp/core/io/flight_data.h"
#include "magcomp/core/model/model.h"
#include "magcomp/core/neural/network.h"

namespace magcomp {

/// What fit_output_gain found on the flights it was given (errors against the model's reference
/// field, each line's mean removed, pooled over the flights, nT).
struct OutputGainFit {
  double gain = 1.0;            ///< in [0, 1]: 0 = the model's terms alone, 1 = as trained
  double unclipped_gain = 1.0;  ///< the least-squares factor before clipping to [0, 1]
  double physics_std_nT = 0.0;  ///< the terms alone (A c)
  double trained_std_nT = 0.0;  ///< the network as trained (gain 1)
  double blended_std_nT = 0.0;  ///< with the fitted gain
  long samples = 0;             ///< finite samples used
};

/// The factor g in [0, 1] minimising the error of correction = A c + g × (network's correction −
/// A c) on `flights` (the model's own output_gain is ignored: the network as trained is g = 1).
/// Each line's mean (field `line`; the whole flight without it) is removed from the errors, as
/// the evaluation's std does. Flights without the reference field are skipped; with no usable
/// sample the gain is 1 and samples is 0. `network`: the trained network (loaded from the model's
/// weights when null).
OutputGainFit fit_output_gain(const Model& model, const std::vector<FlightData>& flights,
                              std::shared_ptr<NeuralNetwork> network = nullptr);

}  // namespace magcomp
