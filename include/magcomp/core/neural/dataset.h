// magcomp: turning flights into standardised windows for training (no torch here).
#pragma once

#include <Eigen/Core>
#include <cstdint>
#include <string>
#include <vector>

#include "magcomp/core/model/model.h"
#include "magcomp/core/neural/features.h"

namespace magcomp {

using RowMatrixXf = Eigen::Matrix<float, Eigen::Dynamic, Eigen::Dynamic, Eigen::RowMajor>;

/// Samples of one or more whole flights, concatenated, ready for the network.
struct TrainingData {
  RowMatrixXf features;                 ///< N x F, standardised, NaN already 0
  Eigen::VectorXf target;               ///< N, standardised target (NaN: not a window end)
  RowMatrixXf tl_columns;               ///< N x P, TL columns / tl_scale (joint mode), else empty
  std::vector<std::int64_t> first_row;  ///< per sample: first sample of its flight (padding)
  std::vector<std::int64_t> ends;       ///< window ends used (finite target, stride applied)
  /// The inputs (feature indices) that read each recorded channel (channel_input_groups):
  /// the groups NeuralTraining::channel_sparsity penalises. Empty: no penalty.
  std::vector<std::vector<std::int64_t>> channel_groups;
  std::vector<std::string> channel_names;  ///< the channel of each group
  std::int64_t windows() const { return static_cast<std::int64_t>(ends.size()); }
};

/// One flight's inputs and target (nT) for training.
struct FlightSamples {
  NeuralInputs inputs;
  Eigen::VectorXd target_nT;
};

/// Each flight's neural inputs and training target for the model (corrections first).
std::vector<FlightSamples> flight_samples(const Model& model,
                                          const std::vector<FlightData>& flights);

/// Fits the spec's normalisation (feature mean and std, target mean and std) on the TRAINING
/// flights only, ignoring NaN. A constant feature gets std 1. Throws magcomp::Error if a feature
/// has no finite value.
void fit_normalisation(NeuralSpec& spec, const std::vector<FlightSamples>& training);

/// RMS of each TL column over the training flights (the joint mode's column scale, nT per unit).
Eigen::VectorXd tl_column_scale(const std::vector<FlightSamples>& training);

/// Concatenates flights into standardised training data; window ends every `stride` samples
/// where the target is finite. tl_scale empty: no TL columns.
TrainingData make_training_data(const NeuralSpec& spec, const std::vector<FlightSamples>& flights,
                                const Eigen::VectorXd& tl_scale, int stride);

}  // namespace magcomp
