// magcomp: in-flight Tolles-Lawson calibration (batch on the collected segments, and recursive
// least squares refined sample by sample).
#pragma once

#include <Eigen/Core>
#include <deque>
#include <memory>
#include <vector>

#include "magcomp/core/math/butterworth.h"
#include "magcomp/core/model/model.h"
#include "magcomp/core/model/stream_sample.h"

namespace magcomp {

/// Collects calibration-maneuver samples as they arrive and keeps two solutions:
/// - batch(): the model's own band-pass + ridge fit on every collected segment, the same numbers as
///   `magcomp calibrate` on those samples;
/// - rls(): recursive least squares on causally band-passed rows (one Butterworth per column, reset
///   at each segment start, `trim` samples skipped), updated every sample with a forgetting factor,
///   started from the ridge prior P0 = I / lambda, so that with forgetting 1 it is a ridge fit too.
/// Inputs: StreamSample with the model's required channels, in time order (s, nT).
class InflightCalibrator {
 public:
  /// `model`: terms and fit settings (band, order, trim, lambda). forgetting in (0, 1].
  InflightCalibrator(Model model, double forgetting);

  /// Adds a sample. `in_segment` says whether it belongs to a calibration maneuver; a segment ends
  /// at the first sample that does not (or at end_segment()).
  void add(const StreamSample& s, bool in_segment);
  void end_segment();
  void reset();

  /// The channels each sample must carry (StreamSample::channels), in this order.
  const std::vector<std::string>& channels() const { return channels_; }
  const Model& model() const { return model_; }
  int segments() const { return segments_; }
  Eigen::Index samples() const { return collected_in_segments_; }
  Eigen::Index rls_updates() const { return rls_updates_; }

  /// The batch solution on every collected segment (throws magcomp::Error when too few samples).
  Model batch() const;
  /// The current recursive solution.
  Model rls() const;

 private:
  void rls_step(const StreamSample& s);

  Model model_;
  double forgetting_;
  std::vector<std::string> channels_;
  std::vector<TermPtr> terms_;  // built once: rls_step() runs per sample
  std::vector<StreamSample> collected_;       // every segment's samples, in order, with one context
                                         // sample before and after each (segment 0: not fitted)
  std::vector<int> segment_of_;             // segment index of each collected sample (0: context)
  std::unique_ptr<StreamSample> previous_;  // the last sample seen (the next segment's context)
  Eigen::Index collected_in_segments_ = 0;
  int segments_ = 0;
  bool in_segment_ = false;
  // RLS state.
  Eigen::VectorXd theta_;
  Eigen::MatrixXd p_;
  std::deque<StreamSample> window_;  // the current segment's last samples (for central differences)
  std::unique_ptr<std::vector<StreamingFilter>> filters_;  // one per column, then the scalar
  Eigen::Index segment_rows_ = 0, rls_updates_ = 0;
};

}  // namespace magcomp
