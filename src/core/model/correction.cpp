// magcomp: a fitted model's correction A c and each sample's variance over a flight (see
// model.h).
#include <algorithm>
#include <cmath>
#include <limits>
#include <thread>

#include "magcomp/core/error.h"
#include "magcomp/core/model/model.h"
#include "magcomp/core/model/quadratic_form.h"

namespace magcomp {

Eigen::VectorXd model_correction(const Model& model, const FlightData& data) {
  Eigen::VectorXd correction;
  model_correction_and_variance(model, data, &correction, nullptr);
  return correction;
}

namespace {
// sample_variance_nT2 with the product's buffer given (per-sample callers).
double row_variance_nT2(const Model& model, const Eigen::Ref<const Eigen::RowVectorXd>& row,
                        Eigen::VectorXd* buffer) {
  const Eigen::MatrixXd& cov = model.report.coefficient_covariance;
  if (cov.rows() != row.size() || !std::isfinite(model.report.noise_variance_nT2)) {
    return std::numeric_limits<double>::quiet_NaN();
  }
  return row_quadratic_form(cov, row, model.report.sample_noise_nT2(), buffer);
}
}  // namespace

double sample_variance_nT2(const Model& model, const Eigen::Ref<const Eigen::RowVectorXd>& row) {
  Eigen::VectorXd buffer;
  return row_variance_nT2(model, row, &buffer);
}

void for_each_correction_block(const Model& model, const FlightData& data, bool with_variance,
                               const std::function<void(Eigen::Index, const Eigen::VectorXd&,
                                                        const Eigen::VectorXd*)>& block) {
  if (!model.fitted()) throw Error("model: not calibrated (no coefficients)");
  const Eigen::MatrixXd& cov = model.report.coefficient_covariance;
  const double noise_nT2 = model.report.sample_noise_nT2();
  // Blocks on two threads (each sample's numbers do not depend on which thread computes them).
  static const int threads =
      static_cast<int>(std::clamp(std::thread::hardware_concurrency(), 1u, 2u));
  for_each_design_block(
      model, data,
      [&](Eigen::Index first, const Eigen::Ref<const Eigen::MatrixXd>& a) {
        if (a.cols() != model.coefficients.size()) {
          throw Error("model: " + std::to_string(model.coefficients.size()) + " coefficients for " +
                      std::to_string(a.cols()) + " columns");
        }
        Eigen::VectorXd correction(a.rows());
        correction.noalias() = a * model.coefficients;
        if (!with_variance) {
          block(first, correction, nullptr);
          return;
        }
        Eigen::VectorXd variance(a.rows());
        if (cov.rows() != a.cols() || !std::isfinite(noise_nT2)) {
          variance.setConstant(std::numeric_limits<double>::quiet_NaN());
        } else {
          row_quadratic_forms(cov, a, noise_nT2, variance.data());
        }
        block(first, correction, &variance);
      },
      threads);
}

void model_correction_and_variance(const Model& model, const FlightData& data,
                                   Eigen::VectorXd* correction_nT, Eigen::VectorXd* variance_nT2) {
  correction_nT->resize(data.size());
  if (variance_nT2) variance_nT2->resize(data.size());
  for_each_correction_block(
      model, data, variance_nT2 != nullptr,
      [&](Eigen::Index first, const Eigen::VectorXd& correction, const Eigen::VectorXd* variance) {
        correction_nT->segment(first, correction.size()) = correction;
        if (variance) variance_nT2->segment(first, variance->size()) = *variance;
      });
}

Eigen::VectorXd compensation_variance_nT2(const Model& model, const FlightData& data) {
  Eigen::VectorXd correction, variance;
  model_correction_and_variance(model, data, &correction, &variance);
  return variance;
}

}  // namespace magcomp
