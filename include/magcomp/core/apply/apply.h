// magcomp: the one way a model is applied to a flight offline.
#pragma once

#include <Eigen/Core>
#include <memory>

#include "magcomp/core/io/flight_data.h"
#include "magcomp/core/model/compensation.h"
#include "magcomp/core/model/model.h"

namespace magcomp {

class NeuralNetwork;

/// Applies any fitted model: its terms (the lag realignment included) and, when it has a trained
/// neural stage, the network on top (libmagcomp_neural is loaded then, or `network` is used).
/// Every offline caller goes through here: compensate(), evaluate, diagnose's reports, the tests;
/// the streaming compensator reproduces it sample by sample. Throws magcomp::Error when the model
/// is not fitted or a field is missing.
Compensation apply_model(const Model& model, const FlightData& data,
                         std::shared_ptr<NeuralNetwork> network = nullptr);

/// Compensated scalar field in nT: apply_model(model, data).compensated_nT: the terms,
/// and the neural stage when the model has a trained one.
Eigen::VectorXd compensate(const Model& model, const FlightData& data);

}  // namespace magcomp
