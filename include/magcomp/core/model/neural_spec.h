// magcomp: the neural stage of a model (the `neural:` block of the model YAML): what the network
// sees, what it predicts, how it is trained, and, once trained, its normalisation and weights.
#pragma once

#include <Eigen/Core>
#include <cstdint>
#include <string>
#include <vector>

namespace magcomp {

struct SignalExpr;

/// Training settings (`neural.training`). Defaults are those of Laoué's report (Adam, batch 256, lr
/// 1e-3 decayed by 0.9 per epoch, MSE).
struct NeuralTraining {
  int epochs = 25;              ///< maximum epochs
  int batch = 256;              ///< windows per batch
  double learning_rate = 1e-3;  ///< Adam, first epoch
  double lr_decay = 0.9;        ///< learning rate multiplied by this after each epoch
  double weight_decay = 1e-2;   ///< Adam weight decay (L2)
  /// Group sparsity on the aircraft's channels (a group lasso): the training loss gains
  /// channel_sparsity × Σ_c sqrt(n_c) ||W_c||, where W_c are the first layer's weights on the
  /// inputs that read recorded channel c (its value, low-passes, products; every time step of
  /// the window) and n_c their count. The network then reads few channels, and of channels that
  /// move together the one that fits best, rather than a share of each (0: off; the model's own
  /// inputs, tl_anomaly, tl_correction, dir_*, are never penalised). Standardised-loss units.
  double channel_sparsity = 0.0;
  /// With channel_sparsity: after the penalised training, a channel whose weights' norm ||W_c||
  /// is below channel_cut × the largest channel's is cut (its weights held at zero) and the
  /// network is trained again from there without the penalty (a relaxed lasso: the penalty
  /// chooses the channels, the refit sizes them unshrunk). 0: no cut, no refit. In [0, 1).
  double channel_cut = 0.0;
  int patience = 5;        ///< early stopping: epochs without a better validation loss
  std::uint64_t seed = 1;  ///< torch and shuffling seed: same seed, same weights
  int stride = 1;          ///< a training window ends every `stride` samples
  int threads = 2;         ///< torch intra-op threads
  /// After training, scale the network's part of the correction by the factor in [0, 1] that
  /// minimises the error on the validation flights (NeuralSpec::output_gain).
  bool fit_output_gain = true;
};

/// The neural stage. Modes:
/// - `anomaly`: the networks of Laoué's report: predict the reference anomaly (reference - IGRF -
/// diurnal)
///   from the features; compensated = IGRF + diurnal + prediction.
/// - `residual`: TL fixed, the network predicts what TL leaves (TL-compensated - reference);
///   correction = A c + prediction (MagNav.jl's "model 2b" idea).
/// - `joint`: as residual, but a change of the TL coefficients is trained with the network;
///   correction = A (c + tl_delta) + prediction (MagNav.jl's "model 2c" idea).
/// - `coefficients`: the network corrects the model's coefficients at every sample from its
///   window: its body outputs one value per model column, δc(t), and correction =
///   A(t) (c + δc(t)) (MagNav.jl's "model 2d" idea, proposed in Laoué's report with a CNN or an
///   RNN as the body).
/// Architectures: Laoué's MLP, CNN and LSTM, and `cnn_lstm`, the stack the report proposes: a
/// convolution over the window (filters hidden[0], kernel 5, ReLU, max-pool 2) feeding an LSTM
/// of hidden[1] units whose last step gives the output.
enum class NeuralArchitecture { kMlp, kCnn, kLstm, kCnnLstm };
enum class NeuralMode { kAnomaly, kResidual, kJoint, kCoefficients };

/// The YAML spellings: mlp, cnn, lstm, cnn_lstm; anomaly, residual, joint, coefficients.
const char* architecture_name(NeuralArchitecture a);
const char* mode_name(NeuralMode m);
/// The enum of a YAML spelling; an Error naming `where` (file: key) and the choices otherwise.
NeuralArchitecture parse_architecture(const std::string& text, const std::string& where);
NeuralMode parse_mode(const std::string& text, const std::string& where);

struct NeuralSpec {
  NeuralArchitecture architecture = NeuralArchitecture::kMlp;
  NeuralMode mode = NeuralMode::kResidual;
  /// Inputs by name: a data field (cur_strb, ins_roll, baro...), `tl_anomaly` (the model's
  /// TL-compensated scalar - IGRF - diurnal, nT), `tl_correction` (A c, nT), `anomaly:<field>`
  /// (field - IGRF - diurnal, nT), `dir_x|dir_y|dir_z` (vector-sensor direction cosines), or a
  /// causal signal of fields in the terms' grammar (`cur_heat|lp(150)`, `cur_a*flap_deg`): an
  /// effect slower than the window, seen through a low-pass of its channel.
  std::vector<std::string> features;
  int window = 5;           ///< samples per window; the window ends at the predicted sample
  std::vector<int> hidden;  ///< mlp: layer widths; cnn: conv filters; lstm: hidden size per layer
  std::string reference = "mag_1_c";  ///< training target field (nT)
  NeuralTraining training;

  // Fitted state, written by `magcomp train`.
  Eigen::VectorXd feature_mean;  ///< per feature, training flights only
  Eigen::VectorXd feature_std;
  double target_mean = 0.0;  ///< nT
  double target_std = 1.0;   ///< nT
  Eigen::VectorXd tl_delta;  ///< joint mode: change of the TL coefficients (model units)
  /// coefficients mode: each model column's rms on the training flights (its units); the
  /// network's outputs are the coefficient corrections of the columns divided by these.
  Eigen::VectorXd column_scale;
  std::string weights;       ///< weights file, relative to the model YAML's directory
  std::string weights_path;  ///< resolved at load (not written)
  int version = 1;           ///< bundle format version
  std::vector<std::string> train_flights, validation_flights;  ///< provenance
  int epochs_run = 0;
  double validation_rmse_nT = 0.0;
  /// The network's share of the correction, in [0, 1]: correction = physics + output_gain ×
  /// (network's correction - physics), where physics is the model's terms alone (A c). Fitted on
  /// the validation flights (each line's mean removed): 0 when the network's gain does not carry
  /// over to a flight it was not trained on, 1 as trained (and for bundles without the key).
  double output_gain = 1.0;

  bool trained() const { return !weights.empty() && feature_mean.size() > 0; }
  /// Hidden sizes, or the architecture's default (mlp 16,4; cnn 16,32; lstm 32,32;
  /// cnn_lstm 16,32).
  std::vector<int> hidden_or_default() const;
};

/// True when a neural feature is a signal of recorded fields (a product 'a*b' or transforms
/// 'a|lp(100)', the terms' signal grammar) rather than one field or a named input.
bool is_signal_feature(const std::string& feature);
/// Parses such a feature: causal (no transform needing later samples), numeric parameters, and
/// recorded fields only. Throws magcomp::Error naming `where`, the key and the feature.
SignalExpr signal_feature(const std::string& feature, const std::string& where);

/// Checks the spec's values (architecture, mode, window, features...). Throws magcomp::Error
/// naming `where` (file) and the key.
void validate_neural_spec(const NeuralSpec& spec, const std::string& where);

}  // namespace magcomp
