// magcomp: checks of the neural stage's settings.
#include "magcomp/core/model/neural_spec.h"

#include <cmath>
#include <set>

#include "magcomp/core/error.h"
#include "magcomp/core/model/signal.h"

namespace magcomp {

const char* architecture_name(NeuralArchitecture a) {
  switch (a) {
    case NeuralArchitecture::kCnn:
      return "cnn";
    case NeuralArchitecture::kLstm:
      return "lstm";
    case NeuralArchitecture::kCnnLstm:
      return "cnn_lstm";
    case NeuralArchitecture::kMlp:
      break;
  }
  return "mlp";
}

const char* mode_name(NeuralMode m) {
  switch (m) {
    case NeuralMode::kAnomaly:
      return "anomaly";
    case NeuralMode::kJoint:
      return "joint";
    case NeuralMode::kCoefficients:
      return "coefficients";
    case NeuralMode::kResidual:
      break;
  }
  return "residual";
}

NeuralArchitecture parse_architecture(const std::string& text, const std::string& where) {
  for (auto a : {NeuralArchitecture::kMlp, NeuralArchitecture::kCnn, NeuralArchitecture::kLstm,
                 NeuralArchitecture::kCnnLstm}) {
    if (text == architecture_name(a)) return a;
  }
  throw Error(where + " must be mlp, cnn, lstm or cnn_lstm, not '" + text + "'");
}

NeuralMode parse_mode(const std::string& text, const std::string& where) {
  for (auto m : {NeuralMode::kAnomaly, NeuralMode::kResidual, NeuralMode::kJoint,
                 NeuralMode::kCoefficients}) {
    if (text == mode_name(m)) return m;
  }
  throw Error(where + " must be anomaly, residual, joint or coefficients, not '" + text + "'");
}

std::vector<int> NeuralSpec::hidden_or_default() const {
  if (!hidden.empty()) return hidden;
  if (architecture == NeuralArchitecture::kCnn || architecture == NeuralArchitecture::kCnnLstm)
    return {16, 32};
  if (architecture == NeuralArchitecture::kLstm) return {32, 32};
  return {16, 4};
}

bool is_signal_feature(const std::string& feature) {
  return feature.find('|') != std::string::npos || feature.find('*') != std::string::npos;
}

SignalExpr signal_feature(const std::string& feature, const std::string& where) {
  const std::string context = where + ": key 'neural.features': '" + feature + "'";
  SignalExpr e = parse_signal(feature, context);
  for (const auto& src : e.sources) {
    if (src == "B" || src == "Bt")
      throw Error(context +
                  ": a feature is a product of recorded fields (the vector sensor's "
                  "components enter as dir_x/y/z)");
  }
  if (e.has_free()) throw Error(context + ": a feature's parameters must be numbers, not '?'");
  if (e.lookahead() > 0)
    throw Error(context + ": a feature must be causal (its transforms need " +
                std::to_string(e.lookahead()) + " sample(s) after each one)");
  return e;
}

void validate_neural_spec(const NeuralSpec& s, const std::string& where) {
  const std::string p = where + ": key 'neural.";
  if (s.features.empty()) throw Error(p + "features' must list at least one input");
  std::set<std::string> seen;
  for (const auto& f : s.features) {
    if (!seen.insert(f).second) throw Error(p + "features' lists '" + f + "' twice");
    if (is_signal_feature(f)) signal_feature(f, where);
  }
  if (s.window < 1 || s.window > 4096) throw Error(p + "window' must be in 1..4096 samples");
  if (s.architecture == NeuralArchitecture::kCnn && s.window < 4)
    throw Error(p + "window' must be >= 4 for a cnn");
  for (int h : s.hidden_or_default()) {
    if (h < 1 || h > 4096) throw Error(p + "hidden' sizes must be in 1..4096");
  }
  if (s.architecture == NeuralArchitecture::kCnn && s.hidden_or_default().size() != 2) {
    throw Error(p + "hidden' of a cnn is its two filter counts, e.g. [16, 32]");
  }
  if (s.architecture == NeuralArchitecture::kCnnLstm) {
    if (s.window < 2) throw Error(p + "window' must be >= 2 for a cnn_lstm");
    if (s.hidden_or_default().size() != 2)
      throw Error(p + "hidden' of a cnn_lstm is its filter count and LSTM units, e.g. [16, 32]");
  }
  if (s.reference.empty()) throw Error(p + "reference' must name the target field");
  const NeuralTraining& t = s.training;
  if (t.epochs < 1) throw Error(p + "training.epochs' must be >= 1");
  if (t.batch < 1) throw Error(p + "training.batch' must be >= 1");
  if (!(t.learning_rate > 0)) throw Error(p + "training.learning_rate' must be > 0");
  if (!(t.lr_decay > 0 && t.lr_decay <= 1)) throw Error(p + "training.lr_decay' must be in (0, 1]");
  if (!(t.weight_decay >= 0)) throw Error(p + "training.weight_decay' must be >= 0");
  if (!(t.channel_sparsity >= 0 && std::isfinite(t.channel_sparsity)))
    throw Error(p + "training.channel_sparsity' must be a finite number >= 0");
  if (!(t.channel_cut >= 0 && t.channel_cut < 1))
    throw Error(p +
                "training.channel_cut' must be in [0, 1) (a fraction of the largest "
                "channel's weight norm)");
  if (t.patience < 1) throw Error(p + "training.patience' must be >= 1");
  if (t.stride < 1) throw Error(p + "training.stride' must be >= 1");
  if (t.threads < 1) throw Error(p + "training.threads' must be >= 1");
  if (!(s.output_gain >= 0.0 && s.output_gain <= 1.0))
    throw Error(p + "output_gain' must be in [0, 1] (the network's share of the correction)");
}

}  // namespace magcomp
