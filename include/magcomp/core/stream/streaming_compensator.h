// magcomp: sample-by-sample compensation for the online path (the same numbers as offline).
#pragma once

#include <Eigen/Core>
#include <cmath>
#include <deque>
#include <memory>
#include <string>
#include <vector>

#include "magcomp/core/model/model.h"
#include "magcomp/core/model/signal.h"
#include "magcomp/core/model/stream_sample.h"
#include "magcomp/core/neural/features.h"
#include "magcomp/core/neural/network.h"

namespace magcomp {

/// The compensation of one sample, nT.
struct StreamOutput {
  double t_s = 0.0;
  double measured_nT = 0.0;     ///< the scalar, realigned by the model's lag
  double correction_nT = 0.0;   ///< A·c
  double compensated_nT = 0.0;  ///< measured - correction
  /// The terms' part A·c of the correction (all of it without a neural stage).
  double tl_correction_nT = 0.0;
  double igrf_nT = NAN;  ///< the sample's igrf_nT, passed through (NaN when not given)
  /// Variance of compensated_nT, nT²: sample_variance_nT2 of the terms' row (model.h); with a
  /// neural stage its validation error². NaN when the model carries no uncertainty.
  double variance_nT2 = NAN;
  /// The model's columns at the sample (A's row, in Model::make_column_names() order): what an
  /// online calibration downstream needs to learn the coefficients.
  Eigen::VectorXd columns;
};

/// Applies a fitted model to a stream of samples. Each output needs a few samples after it
/// (central differences, the lag realignment): lookahead() samples of latency. The terms'
/// columns are built on a sliding window with the batch code, and the signals of language terms
/// with transforms (low-pass, integral, delay, ...) run through the same causal recursion as the
/// batch one, kept from the stream's first sample, so a whole stream reproduces compensate() on
/// the same flight exactly (one-sided differences at both ends included).
class StreamingCompensator {
 public:
  /// Throws magcomp::Error if the model is not fitted. A model with a trained neural stage
  /// loads libmagcomp_neural (or uses `network` when given) and runs it at batch 1 on a ring
  /// buffer of its window.
  explicit StreamingCompensator(Model model, std::shared_ptr<NeuralNetwork> network = nullptr);

  const Model& model() const { return model_; }
  /// True when samples must carry igrf_nT (a neural stage that removes the core field).
  bool needs_igrf() const { return plan_ && plan_->needs_igrf(); }
  /// True when the model has a neural stage.
  bool has_network() const { return static_cast<bool>(streamer_); }
  /// Channels the model's terms and neural features need (e.g. cur_strb for current:cur_strb);
  /// the model's own scalar and vector fields are not among them (they come in every sample).
  const std::vector<std::string>& required_channels() const { return channels_; }
  /// Samples of latency (0 until the sample period is known, after the second sample).
  int lookahead() const { return half_; }

  /// Adds the next sample (stamps must increase; the caller rejects others). Returns the outputs
  /// that became ready, oldest first.
  std::vector<StreamOutput> push(const StreamSample& sample);
  /// Emits every pending sample (end of stream, or before a reset after a gap or a time jump).
  std::vector<StreamOutput> flush();
  /// Forgets everything (pending samples are dropped: flush() first to keep them).
  void reset();
  size_t pending() const { return buffer_.size() - static_cast<size_t>(next_); }

 private:
  StreamOutput emit(Eigen::Index index);
  /// Feeds a sample's sources to the streamed signals; their outputs land in derived_.
  void feed_signals(const StreamSample& sample);
  void store_signal(size_t signal, int component, double value);

  /// A language term's signal computed by its causal chains (one per component).
  struct StreamedSignal {
    std::vector<std::string> sources;  // "B", "Bt", the scalar, vector components or channels
    std::vector<int> source_kind;      // 0: channel (index in source_index), 1: B, 2: Bt,
                                       // 3: scalar, 4..6: vector component x, y, z
    std::vector<int> source_index;
    std::vector<std::unique_ptr<TransformChain>> chains;
    std::vector<long long> next_output;  // global sample index of each chain's next output
    size_t first_column = 0;             // its first component's slot in derived_ rows
    std::vector<std::string> columns;    // window column names (ExprTerm::stream_column)
  };
  Model model_;
  std::vector<TermPtr> terms_;  // built once: emit() runs per sample
  double lag_s_ = 0.0;
  std::vector<std::string> channels_;
  std::unique_ptr<FeaturePlan> plan_;         // neural stage only
  std::unique_ptr<NeuralStreamer> streamer_;  // neural stage only
  std::vector<double> feature_row_;
  std::deque<StreamSample> buffer_;
  std::vector<StreamedSignal> signals_;
  size_t derived_columns_ = 0;
  std::deque<std::vector<double>> derived_;  // per buffer_ sample: the streamed signals' values
  long long base_index_ = 0;                 // global index of buffer_[0]
  int signal_lookahead_ = 0;
  Eigen::Index next_ = 0;  // index in buffer_ of the next sample to emit
  int half_ = 0;           // samples needed on each side of an emitted one
};

}  // namespace magcomp
