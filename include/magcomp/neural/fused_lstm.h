// magcomp: a multi-layer LSTM over whole windows whose backward pass is written out (back-
// propagation through time in one autograd node), for training on the CPU (libmagcomp_neural).
//
// The function is torch::nn::LSTM's (batch first, torch's gate order input, forget, cell, output,
// zero initial state), returning the top layer's output at the last step. libtorch's CPU LSTM
// records about ten autograd nodes per step and layer and runs each as a separate small kernel;
// here each layer, held time-major, is two large matrix products over every step (the input
// projection, then the weights' gradients) around a recurrence that runs in one pass per batch
// chunk, the chunks in parallel on torch's intra-op threads.
#pragma once

#include <torch/torch.h>

#include <vector>

namespace magcomp {

/// x [B, T, F] (float32 or float64); `weights` per layer: weight_ih [4H, in], weight_hh [4H, H],
/// bias_ih [4H], bias_hh [4H] (torch::nn::LSTM's parameters, in that order). Returns [B, H]: the
/// top layer's output at step T. Differentiable in the weights (and in x when it requires grad).
torch::Tensor fused_lstm_last(const torch::Tensor& x, const std::vector<torch::Tensor>& weights);

}  // namespace magcomp
