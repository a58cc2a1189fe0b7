// magcomp: training a neural stage (implemented in libmagcomp_neural with libtorch; this header
// has no torch in it, so callers compile in a second).
#pragma once

#include <Eigen/Core>
#include <cmath>
#include <cstdint>
#include <string>
#include <vector>

#include "magcomp/core/model/model.h"
#include "magcomp/core/model/neural_spec.h"
#include "magcomp/core/neural/dataset.h"
#include "magcomp/core/neural/output_gain.h"

namespace magcomp {

/// What a training run did.
struct TrainResult {
  std::vector<double> train_rmse_nT;       ///< per epoch, on the training windows
  std::vector<double> validation_rmse_nT;  ///< per epoch (empty without validation)
  int best_epoch = 0;                      ///< 1-based epoch whose weights were kept
  int epochs_run = 0;
  double seconds = 0.0;
  Eigen::VectorXd tl_weights;  ///< joint mode: weights on the scaled TL columns (standardised)
  /// channel_cut: the channels kept after the penalised epochs, largest weight norm first, and
  /// the number cut; refit_from_epoch: the first epoch trained without the penalty (0: none).
  std::vector<std::string> kept_channels;
  int cut_channels = 0;
  int refit_from_epoch = 0;
  double best_validation_rmse_nT = NAN;  ///< of the weights kept (NaN without validation)
};

/// Trains the spec's network (seeded: same inputs, same weights) and writes its weights to
/// `weights_path` atomically (temporary file + rename). Early stopping on `validation` when it
/// has windows. `progress`: a progress bar with loss and ETA on stderr.
TrainResult train_network(const NeuralSpec& spec, const TrainingData& train,
                          const TrainingData& validation, const std::string& weights_path,
                          bool progress);

/// One epoch of training over `data` with the spec's settings, timed, s (the benchmark).
/// `torch_lstm`: an LSTM through torch::nn::LSTM's own backward instead of fused_lstm_last.
double time_one_epoch(const NeuralSpec& spec, const TrainingData& data, bool torch_lstm = false);

}  // namespace magcomp

namespace magcomp {

/// What train_bundle did (for the command line and the tests).
struct BundleReport {
  TrainResult result;
  std::string yaml_path, weights_path;
  Eigen::Index train_windows = 0, validation_windows = 0;
  bool tl_fitted_here = false;
  /// The network's share of the correction fitted on the validation flights (samples 0 when it
  /// was not fitted: no validation flight, or neural.training.fit_output_gain false).
  OutputGainFit output_gain;
};

/// The whole of `magcomp train`: calibrates TL on the training flights if the model is not
/// fitted, computes features and target (corrections first), fits the normalisation on the
/// training flights only, trains, fits the network's share of the correction on the validation
/// flights (NeuralSpec::output_gain), and writes the bundle (weights first, then the model YAML,
/// both atomically). `out`: OUT.yaml (weights OUT.pt beside it) or a directory (model.yaml +
/// weights.pt). Updates `model` to the trained one. Throws magcomp::Error on bad input.
BundleReport train_bundle(Model& model, const std::vector<FlightData>& train_flights,
                          const std::vector<FlightData>& validation_flights, const std::string& out,
                          bool progress);

}  // namespace magcomp
