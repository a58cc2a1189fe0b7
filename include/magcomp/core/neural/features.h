// magcomp: the neural stage's inputs and target, computed the same way offline (whole flights)
// and online (one sample at a time), so the two paths give the same numbers.
#pragma once

#include <Eigen/Core>
#include <cstdint>
#include <memory>
#include <string>
#include <utility>
#include <vector>

#include "magcomp/core/geo/igrf.h"
#include "magcomp/core/geo/igrf_track.h"
#include "magcomp/core/io/flight_data.h"
#include "magcomp/core/model/model.h"
#include "magcomp/core/model/signal.h"

namespace magcomp {

/// How each feature named in `neural.features` is computed from one sample.
class FeaturePlan {
 public:
  /// Throws magcomp::Error if the model has no neural stage or names an unknown feature form.
  explicit FeaturePlan(const Model& model);

  /// Data fields the features need besides the model's scalar and vector sensors (raw features,
  /// the fields of anomaly:<field>, and `diurnal` when a correction uses it), in a fixed order.
  const std::vector<std::string>& fields() const { return fields_; }
  /// True when some feature or the target needs the IGRF total field at the sample.
  bool needs_igrf() const { return needs_igrf_; }
  size_t size() const { return items_.size(); }

  /// Finds fields() in a list of channel names (the order of the values given to row()).
  /// Throws magcomp::Error naming `where` and the first missing field.
  void bind(const std::vector<std::string>& channel_names, const std::string& where);

  /// One raw feature row (units of each feature: nT, data units for fields). Inputs: the sample's
  /// time, s; the scalar realigned by the model's lag, nT; the TL correction A c, nT; the IGRF
  /// total field, nT (NaN if unknown); the vector sensor, nT; the channel values in bind()'s
  /// order. Rows must come in time order: a signal feature's transforms (low-pass, decay...)
  /// carry state from one row to the next, the same recursion offline and online.
  void row(double t_s, double scalar_nT, double tl_correction_nT, double igrf_nT,
           const Eigen::Vector3d& vector_nT, const double* channels, double* out);
  /// Starts the signal features' transforms afresh (a new flight or stream).
  void reset();
  /// The recorded fields each feature reads (empty for the model's own inputs: tl_anomaly,
  /// tl_correction, dir_*, anomaly:<field>, the vector components), in the features' order.
  const std::vector<std::vector<std::string>>& feature_channels() const { return channels_; }
  /// Diurnal field at the sample, nT (0 when the data has none or it is NaN).
  double diurnal_nT(const double* channels) const;

 private:
  enum class Kind { kField, kTlAnomaly, kTlCorrection, kAnomalyOf, kDirection, kSignal };
  struct Item {
    Kind kind;
    int field = -1;  // index in fields_
    int axis = 0;
    std::vector<int> sources;               // kSignal: indices in fields_, multiplied
    std::unique_ptr<TransformChain> chain;  // kSignal: its transforms (none: a plain product)
  };
  int field_index(const std::string& name);
  std::vector<Item> items_;
  std::vector<std::string> fields_;
  std::vector<std::vector<std::string>> channels_;
  std::vector<int> bound_;  // fields_[k] is channel bound_[k]
  int diurnal_field_ = -1;
  bool needs_igrf_ = false;
};

/// The recorded channels the model's neural features read, in the order they first appear, each
/// with the indices of the features that read it (a product's feature is in each of its
/// channels' groups). The model's own inputs (tl_anomaly, tl_correction, dir_*, anomaly:<field>)
/// belong to none. Throws as FeaturePlan does.
std::vector<std::pair<std::string, std::vector<std::int64_t>>> channel_input_groups(
    const Model& model);

/// Everything the neural stage needs from one flight, as whole columns.
struct NeuralInputs {
  Eigen::VectorXd scalar_nT;      ///< realigned by the model's lag
  Eigen::MatrixXd tl_columns;     ///< the terms' design matrix A
  Eigen::VectorXd correction_nT;  ///< A c
  Eigen::VectorXd igrf_nT;        ///< NaN when not needed
  Eigen::VectorXd diurnal_nT;
  Eigen::MatrixXd features;  ///< N x F raw features
};
/// Computes the inputs; throws magcomp::Error naming the file and any feature the data lacks.
NeuralInputs neural_inputs(const Model& model, const FlightData& data);

/// The training target of the model's mode at each sample, nT (NaN where unknown): the
/// reference anomaly (anomaly mode) or TL-compensated - reference (residual, joint). Throws if
/// the data lacks the reference field.
Eigen::VectorXd neural_target(const Model& model, const FlightData& data, const NeuralInputs& in);

/// Standardises a raw feature row with the spec's normalisation; NaN becomes 0 (the mean).
void standardise_features(const NeuralSpec& spec, const double* raw, double* out);

}  // namespace magcomp
