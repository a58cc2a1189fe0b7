// magcomp: a model applied to a whole flight: what apply_model and the neural stage return.
#pragma once

#include <Eigen/Core>

namespace magcomp {

/// A model applied to a whole flight, every sample, nT.
struct Compensation {
  Eigen::VectorXd measured_nT;          ///< the scalar realigned by the model's lag
  Eigen::VectorXd terms_correction_nT;  ///< A c: the terms' part of the correction
  Eigen::VectorXd correction_nT;        ///< the whole correction (terms, and the network if any)
  Eigen::VectorXd compensated_nT;       ///< measured - correction
  Eigen::VectorXd network_nT;           ///< the network's prediction (empty without a neural stage)
};

}  // namespace magcomp
