// magcomp: the network architectures (libtorch). Private to libmagcomp_neural.
#pragma once

#include <torch/torch.h>

#include "magcomp/core/model/neural_spec.h"

namespace magcomp {

/// One network of any architecture: forward(windows [B, k, F], tl [B, P] or undefined) -> [B].
/// n_tl_columns: in joint mode, the TL columns' linear layer (tl_linear); in coefficients mode,
/// the body's outputs (one coefficient correction per model column), dotted with tl.
struct CompensatorNetImpl : torch::nn::Module {
  CompensatorNetImpl(const NeuralSpec& spec, int n_features, int n_tl_columns);
  torch::Tensor forward(const torch::Tensor& windows, const torch::Tensor& tl);
  /// The first layer's weights on each input, [R, F]: column f holds every weight that reads
  /// input f (each unit and time step of the MLP's first layer or the convolution, or each gate
  /// of the first LSTM layer). What NeuralTraining::channel_sparsity penalises.
  torch::Tensor input_weights();
  /// Sets to zero every first-layer weight that reads the inputs `columns` (int64 indices):
  /// those inputs are cut from the network (channel_cut).
  void zero_inputs(const torch::Tensor& columns);

  NeuralArchitecture architecture;
  bool coefficients = false;  ///< the body's outputs are coefficient corrections
  int window = 1;
  int n_features = 0;
  torch::nn::Sequential mlp{nullptr};
  torch::nn::Conv1d conv1{nullptr}, conv2{nullptr};
  torch::nn::Linear cnn_fc1{nullptr}, cnn_fc2{nullptr};
  torch::nn::LSTM lstm{nullptr};
  /// The LSTM on float32 windows (training, validation) through fused_lstm_last; false: through
  /// torch::nn::LSTM (the same function; double-precision inference always takes torch's).
  bool fused_lstm = true;
  torch::nn::Linear lstm_fc{nullptr};
  torch::nn::Linear tl_linear{nullptr};  // joint mode: weights on the scaled TL columns
};
TORCH_MODULE(CompensatorNet);

}  // namespace magcomp
