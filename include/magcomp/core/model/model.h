// magcomp: a compensation model (scalar sensor + vector sensor + terms + fit settings +
// coefficients).
#pragma once

#include <Eigen/Core>
#include <functional>
#include <memory>
#include <optional>
#include <string>
#include <utility>
#include <vector>

#include "magcomp/core/io/flight_data.h"
#include "magcomp/core/model/neural_spec.h"
#include "magcomp/core/model/term.h"
#include "magcomp/core/model/term_spec.h"

namespace magcomp {

/// The fit's target: the band-passed scalar on calibration segments (`bandpass`), or the scalar
/// minus a reference field (`reference`).
enum class FitMethod { kBandpass, kReference };

/// The YAML spelling of a fit method ("bandpass", "reference").
const char* fit_method_name(FitMethod m);

/// How the coefficients are fitted (the `fit:` block of the model YAML).
struct FitSettings {
  FitMethod method = FitMethod::kBandpass;
  std::vector<double> lines;        ///< calibration segments by line number
  std::vector<TimeWindow> windows;  ///< and/or by tt windows, s
  double band_low_hz = 0.1;         ///< band-pass only
  double band_high_hz = 0.9;
  int order = 4;          ///< Butterworth prototype order
  int trim = 20;          ///< samples dropped at each end of each filtered segment
  double lambda = 0.025;  ///< ridge parameter (dimensionless, on the raw columns)
  std::string reference;  ///< reference field name, reference method only
  /// Lines (by line number) whose rows the slow stage (Model::slow_terms) is also fitted on,
  /// beside the calibration segments: survey lines, where a drift of minutes shows its slope,
  /// each line's mean removed. The band-pass stage never reads them. Empty: calibration only.
  std::vector<double> slow_lines;
};

/// What a fit reports about its conditioning.
struct FitReport {
  Eigen::Index samples = 0;            ///< rows used in the regression
  int segments = 0;                    ///< contiguous calibration segments used
  double condition_number = 0.0;       ///< of the column-normalised design matrix
  double residual_std_nT = 0.0;        ///< std of the fit residual (filtered for bandpass)
  std::vector<std::string> warnings;   ///< e.g. terms the segments do not excite
  std::vector<std::string> estimates;  ///< free parameters (?) the fit estimated, in words
  /// Variance of the fit's residual, nT² (residual sum of squares / (rows - coefficients)). For a
  /// reference fit it is the noise of the compensated field; for a band-pass fit the noise in the
  /// band only, which understates broadband noise.
  double noise_variance_nT2 = NAN;
  /// Covariance of the coefficients, nT² per (column unit)², P x P in column order: the ridge
  /// estimator's noise_variance (A'A + lambda I)^-1 A'A (A'A + lambda I)^-1 (zero for the columns
  /// the method cannot fit). Empty when unknown.
  Eigen::MatrixXd coefficient_covariance;
  /// Variance of the model's error on the lines it was not fitted on, against a reference (line
  /// means removed), nT²: the noise and what the model misses (an effect it lacks), as measured
  /// where the fit could not adapt to it. NaN when unknown.
  double holdout_error_variance_nT2 = NAN;
  /// The variance every sample's uncertainty adds to its coefficients' part, nT²: the held-out
  /// error where known (a band-pass fit's residual counts the anomaly in its band and misses what
  /// the terms cannot express), else the fit's noise.
  double sample_noise_nT2() const {
    return std::isfinite(holdout_error_variance_nT2) ? holdout_error_variance_nT2
                                                     : noise_variance_nT2;
  }
};

/// A compensation model. Its terms are parsed once (TermSpec) and shared by the designs built
/// from them.
struct Model {
  std::string scalar = "mag_5_uc";  ///< field of the scalar magnetometer, nT
  std::string vector = "flux_c";    ///< vector magnetometer prefix: <vector>_x/_y/_z, nT
  std::vector<TermSpec> terms = {"permanent", "induced", "eddy"};
  /// The terms (among `terms`) that make up a learned law: hinges of a channel whose sum is a
  /// fitted shape, not a physical law (diagnose adds them when no term of the language passes).
  /// Written as `black_box_terms` in the model file.
  std::vector<std::string> black_box_terms;
  /// The terms (among `terms`) too slow for the calibration segments to size (a heater's
  /// hundreds of seconds, a drift): left out of the fit's first stage (the band-pass stage, or
  /// the reference fit of the other columns) and fitted after it against fit.reference on the
  /// same calibration segments and fit.slow_lines, unfiltered, each segment's and line's mean
  /// removed (fit_slow_stage). Written as `slow_terms` in the model file.
  std::vector<std::string> slow_terms;
  double bt_scale_nT = 50000.0;
  FitSettings fit;
  // Fitted state (empty until calibrated).
  std::vector<std::string> column_names;
  Eigen::VectorXd coefficients;
  FitReport report;
  /// Optional neural stage on top of the terms (see magcomp/core/model/neural_spec.h).
  std::optional<NeuralSpec> neural;

  bool fitted() const { return coefficients.size() > 0; }
  /// The term objects, in order (shared with `terms`: nothing is parsed again).
  std::vector<TermPtr> make_terms() const;
  /// Names of all columns the terms build, in order.
  std::vector<std::string> make_column_names() const;
  /// Scalar lag behind the vector sensor the terms declare (lag:<s>), s.
  double scalar_lag_s() const;
  /// Adds a term spec if not yet present (validated). Returns false if it was already there. A
  /// lag replaces the model's lag; a language term replaces one of the same shape (the same
  /// expression with other parameter values, e.g. field:cur_heat|lp(80) replaces |lp(60)). A
  /// parsed term is kept as it is (written canonically), not parsed again.
  bool add_term(const TermSpec& term);
  /// Adds a term (add_term) as a slow term (slow_terms), fitted against fit.reference, which
  /// gets `reference` when the model names none. Throws magcomp::Error for a term with a free
  /// parameter (require_slow_term).
  void add_slow_term(const TermSpec& term, const std::string& reference);
};

/// Throws magcomp::Error when `term` cannot be a slow term: one with a free parameter (?), which
/// the slow stage, fitting coefficients only, cannot estimate.
void require_slow_term(const TermSpec& term);

/// Loads a model YAML (a plain or a fitted one), or a bundle directory holding model.yaml (and
/// the neural stage's weights). Throws magcomp::Error naming file and key.
Model load_model_yaml(const std::string& path);
/// Writes the model (and coefficients, when fitted) atomically: temporary file + rename, never
/// over one of `inputs` or a non-regular file (file_io.h). A neural stage's weights are not
/// written here (magcomp train writes them first, then this file).
void save_model_yaml(const Model& model, const std::string& path,
                     const std::vector<std::string>& inputs = {});

/// The N x P design matrix of the model's terms on a whole flight (rows may hold NaN where inputs
/// are NaN). With a fractional lag:<s> term the columns carry the lag's round trip
/// (lag_round_trip, timeseries.h), as the realigned scalar does. Throws magcomp::Error naming the
/// file and the missing field.
Eigen::MatrixXd design_matrix(const Model& model, const FlightData& data);
/// The same with the model's terms already built (per-sample callers build them once).
Eigen::MatrixXd design_matrix(const Model& model, const std::vector<TermPtr>& terms,
                              const FlightData& data);

/// Indices of the design-matrix columns of `terms` that a fit by `method` can fit: all of them
/// for a reference fit; for a band-pass fit only those of bandpass_observable() terms (a bias,
/// say, is filtered away).
std::vector<Eigen::Index> fittable_columns(FitMethod method, const std::vector<TermPtr>& terms);
/// The same, without the columns of `slow_terms` (the slow stage fits those, after the others).
std::vector<Eigen::Index> fittable_columns(FitMethod method, const std::vector<TermPtr>& terms,
                                           const std::vector<std::string>& slow_terms);
/// Indices of the design-matrix columns of the model's slow terms (Model::slow_terms), which a fit
/// by either method fits after its first stage (the band-pass stage, or the reference fit of the
/// other columns on the calibration rows), on the calibration rows and fit.slow_lines.
std::vector<Eigen::Index> slow_columns(const std::vector<TermPtr>& terms,
                                       const std::vector<std::string>& slow_terms);

/// Samples of margin that make rows of the design matrix and of the aligned scalar built on a
/// slice of a flight (FlightData::rows) equal to the same rows built on the whole flight: the
/// terms' row reach plus the lag's shift plus the interpolation's (and the columns' lag round
/// trip, timeseries.h); -1 when a term depends on the
/// whole history (a causal filter), so only the whole flight gives its values.
Eigen::Index slice_margin(const Model& model, const std::vector<TermPtr>& terms, double dt_s);

/// Calls `block(first, a)` for consecutive blocks of rows covering the flight, `a` being rows
/// [first, first + a.rows()) of the design matrix. Each block is built on a slice with the
/// model's margin, so memory stays at one block per thread; a model with a history-dependent
/// term gets the whole matrix as one block. The numbers equal design_matrix()'s. With threads > 1
/// the blocks are built and passed on that many threads at once (`block` must then be safe to call
/// concurrently for different blocks); the first exception is rethrown.
void for_each_design_block(
    const Model& model, const FlightData& data,
    const std::function<void(Eigen::Index, const Eigen::Ref<const Eigen::MatrixXd>&)>& block,
    int threads = 1);

/// The model's scalar field (nT) realigned to the vector sensor: s(t + lag) when the model has a
/// lag:<s> term (cubic interpolation; NaN where the realigned time falls past the flight's end).
Eigen::VectorXd aligned_scalar(const Model& model, const FlightData& data);
/// The same with the model's lag (Model::scalar_lag_s()) already known, s.
Eigen::VectorXd aligned_scalar(const Model& model, const FlightData& data, double lag_s);

/// Aircraft correction in nT at every sample: A c (compensated = scalar - correction).
Eigen::VectorXd model_correction(const Model& model, const FlightData& data);

/// Variance of one compensated sample, nT²: the coefficients' uncertainty propagated through the
/// sample's design row (a Cov a') plus the fit's noise variance. NaN when the model has no
/// uncertainty (fitted before it was recorded) or the row is not finite.
double sample_variance_nT2(const Model& model, const Eigen::Ref<const Eigen::RowVectorXd>& row);
/// The same for every sample of a flight, nT².
Eigen::VectorXd compensation_variance_nT2(const Model& model, const FlightData& data);
/// model_correction() and compensation_variance_nT2() in one pass over the design matrix (nT,
/// nT²); `variance_nT2` may be null.
void model_correction_and_variance(const Model& model, const FlightData& data,
                                   Eigen::VectorXd* correction_nT, Eigen::VectorXd* variance_nT2);
/// The same block by block, on up to two threads, holding one block per thread: calls
/// `block(first, correction_nT, variance_nT2)` for consecutive rows [first, first +
/// correction_nT.size()) covering the flight (variance_nT2 null unless `with_variance`; NaN rows
/// without an uncertainty). Each row's numbers equal model_correction_and_variance()'s; `block`
/// must be safe to call concurrently for different blocks.
void for_each_correction_block(
    const Model& model, const FlightData& data, bool with_variance,
    const std::function<void(Eigen::Index first, const Eigen::VectorXd& correction_nT,
                             const Eigen::VectorXd* variance_nT2)>& block);

}  // namespace magcomp
