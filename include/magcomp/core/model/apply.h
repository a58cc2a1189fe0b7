// magcomp: the one way a model is applied to a flight offline.
#pragma once

#include <Eigen/Core>
#include <memory>

#include "magcomp/core/io/flight_data.h"
#include "magcomp/core/model/model.h"

namespace magcomp {

class NeuralNetwork;

/// A model applied to a whole flight, every sample, nT.
struct Compensation {
  Eigen::VectorXd measured_nT;          ///< the scalar realigned by the model's lag
  Eigen::VectorXd terms_correction_nT;  ///< A c: the terms' part of the correction
  Eigen::VectorXd correction_nT;        ///< the whole correction (terms, and the network if any)
  Eigen::VectorXd compensated_nT;       ///< measured - correction
  Eigen::VectorXd network_nT;           ///< the network's prediction (empty without a neural stage)
};

/// Applies any fitted model: its terms (the lag realignment included) and, when it has a trained
/// neural stage, the network on top (libmagcomp_neural is loaded then, or `network` is used).
/// Every offline caller goes through here: compensate(), evaluate, diagnose's reports, the tests;
/// the streaming compensator reproduces it sample by sample. Throws magcomp::Error when the model
/// is not fitted or a field is missing.
Compensation apply_model(const Model& model, const FlightData& data,
                         std::shared_ptr<NeuralNetwork> network = nullptr);

}  // namespace magcomp
