// magcomp: applying a model offline.
#include "magcomp/core/apply/apply.h"

#include "magcomp/core/neural/network.h"

namespace magcomp {

Compensation apply_model(const Model& model, const FlightData& data,
                         std::shared_ptr<NeuralNetwork> network) {
  if (model.neural && model.neural->trained()) return neural_compensate(model, data, network);
  Compensation c;
  c.measured_nT = aligned_scalar(model, data);
  c.terms_correction_nT = model_correction(model, data);
  c.correction_nT = c.terms_correction_nT;
  c.compensated_nT = c.measured_nT - c.correction_nT;
  return c;
}

Eigen::VectorXd compensate(const Model& model, const FlightData& data) {
  return apply_model(model, data).compensated_nT;
}

}  // namespace magcomp
