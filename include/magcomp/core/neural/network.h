// magcomp: the neural stage at run time. The network itself lives in libmagcomp_neural (libtorch),
// loaded with dlopen only when a model has a neural stage, so TL-only tools and nodes never pay
// libtorch's start-up (~0.6 s, ~160 MB).
#pragma once

#include <Eigen/Core>
#include <cstdint>
#include <memory>
#include <string>
#include <vector>

#include "magcomp/core/io/flight_data.h"
#include "magcomp/core/model/compensation.h"
#include "magcomp/core/model/model.h"

namespace magcomp {

/// A trained network: standardised windows in, standardised predictions out.
class NeuralNetwork {
 public:
  virtual ~NeuralNetwork() = default;
  /// windows: count x window x features, row-major (oldest sample first, features fastest);
  /// out: count predictions (standardised target). Runs in double precision. columns: in
  /// coefficients mode, count x P model columns at each window's last sample divided by the
  /// spec's column_scale (row-major): the prediction is the network's P outputs dotted with
  /// them. Ignored (may be null) in the other modes.
  virtual void predict(const double* windows, std::int64_t count, double* out,
                       const double* columns) = 0;
};

/// Loads the network of a trained model's neural stage from its weights file, through
/// libmagcomp_neural (found beside the executable's lib directory, on LD_LIBRARY_PATH, or at
/// $MAGCOMP_NEURAL_LIB). Throws magcomp::Error naming the model or library at fault.
std::shared_ptr<NeuralNetwork> load_neural_network(const Model& model, int n_features);

/// The symbol libmagcomp_neural exports; returns nullptr and fills `error` on failure.
using CreateNetworkFn = NeuralNetwork* (*)(const NeuralSpec* spec, int n_features,
                                           std::string* error);
constexpr const char* kCreateNetworkSymbol = "magcomp_create_network";

/// A model with a neural stage applied to a whole flight (model/compensation.h), nT.
using NeuralCompensation = Compensation;
/// Offline inference (apply_model calls it for a model with a trained neural stage): windows end
/// at each sample and are padded at the flight's start by repeating its first sample (the online
/// path does the same after each reset).
NeuralCompensation neural_compensate(const Model& model, const FlightData& data,
                                     std::shared_ptr<NeuralNetwork> network = nullptr);

/// A flight's raw feature rows (N x F) standardised with the spec's normalisation, one sample per
/// column (F x N): what the network's windows are cut from.
Eigen::MatrixXd standardised_inputs(const NeuralSpec& spec, const Eigen::MatrixXd& features);
/// The network's output at every sample, nT (its target's units: the residual of the terms, or
/// the anomaly), from standardised inputs z (F x N): windows end at each sample and are padded at
/// the start by repeating the first sample, as neural_compensate does.
/// columns: the model's design matrix A (N x P), which the coefficients mode needs (null in
/// the others).
Eigen::VectorXd network_output_nT(const NeuralSpec& spec, const Eigen::MatrixXd& z,
                                  NeuralNetwork& network, const Eigen::MatrixXd* columns = nullptr);

/// Coefficients mode: the network's correction of each model coefficient at every sample, δc(t)
/// (N x P, in each coefficient's own units), so that its prediction is A(t) δc(t) plus the
/// target's mean. What the network learned, read as physics: e.g. the permanent-field
/// coefficients following a current are a wire. Throws for another mode.
Eigen::MatrixXd coefficient_corrections(const Model& model, const FlightData& data,
                                        std::shared_ptr<NeuralNetwork> network = nullptr);

/// Maps the network's prediction y (nT) to the total correction, given the sample's realigned
/// scalar, TL correction A c, A·tl_delta, IGRF and diurnal (nT); the spec's output_gain blends it
/// with the terms' correction A c (1: the network as trained).
double neural_correction_nT(const NeuralSpec& spec, double scalar_nT, double tl_correction_nT,
                            double tl_delta_nT, double igrf_nT, double diurnal_nT, double y_nT);

/// Online inference at batch 1: a ring buffer of the last `window` standardised feature rows.
class NeuralStreamer {
 public:
  NeuralStreamer(const NeuralSpec& spec, std::shared_ptr<NeuralNetwork> network);
  /// Adds a raw feature row and returns the network's prediction for it, nT. columns: the
  /// sample's model columns (a row of A, P values), which the coefficients mode needs.
  double push(const double* raw_features, const double* columns = nullptr);
  /// Forgets the window (after a gap or a time jump); the next row is padded as at a start.
  void reset() { filled_ = false; }

 private:
  const NeuralSpec spec_;
  std::shared_ptr<NeuralNetwork> network_;
  std::vector<double> window_;   // window x features, oldest row first
  std::vector<double> columns_;  // the sample's model columns / column_scale (coefficients)
  bool filled_ = false;
};

}  // namespace magcomp
