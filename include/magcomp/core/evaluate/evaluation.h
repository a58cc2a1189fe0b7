// magcomp: compare a compensated signal with a reference, overall and per line.
#pragma once

#include <Eigen/Core>
#include <string>
#include <vector>

#include "magcomp/core/evaluate/figure_of_merit.h"
#include "magcomp/core/io/flight_data.h"
#include "magcomp/core/math/constants.h"
#include "magcomp/core/model/model.h"

namespace magcomp {

/// Error statistics of one flight line (nT). std removes the line's mean (as MagNav.jl reports).
struct LineStats {
  double line = 0.0;
  Eigen::Index n = 0;  ///< finite samples
  double rmse_nT = 0.0;
  double std_nT = 0.0;                ///< NaN for a line of one sample (no spread to measure)
  double uncompensated_std_nT = NAN;  ///< the same for the scalar before compensation
  double improvement_ratio = NAN;     ///< uncompensated_std_nT / std_nT
};

/// Error statistics of a group of samples (a flight condition, a heading sector), nT. std_nT is
/// the rms of the error after removing each line's mean (so groups compare without the offsets).
struct GroupStats {
  std::string name;
  Eigen::Index n = 0;
  double std_nT = 0.0;
};

/// A model's error against a reference on a flight. error = compensated - truth, nT.
struct Evaluation {
  double rmse_nT = 0.0;  ///< raw RMS of the error over finite samples
  double std_nT = 0.0;   ///< RMS after removing each line's mean
  Eigen::Index n = 0;    ///< finite samples
  Eigen::Index nan_samples = 0;
  std::vector<LineStats> per_line;
  std::vector<GroupStats> per_condition;  ///< straight_level, turn, climb_descent, maneuver_*
  std::vector<GroupStats> per_heading;    ///< N, NE, ... NW
  Eigen::VectorXd compensated_nT;
  Eigen::VectorXd error_nT;
  /// Uncompensated error std (the realigned scalar against the truth, line means removed) and
  /// the improvement ratio uncompensated / compensated std, over every line.
  double uncompensated_std_nT = NAN;
  double improvement_ratio = NAN;
  /// Per-sample variance of the compensated field (model.h sample_variance_nT2), nT², and the
  /// fraction of finite errors, each line's mean removed, within 1 and 2 sigma of it (NaN without
  /// an uncertainty).
  Eigen::VectorXd variance_nT2;
  double coverage_1sigma = NAN, coverage_2sigma = NAN;
  /// The figure of merit on the model's calibration maneuvers.
  FigureOfMerit fom;
};

/// Statistics of `error_nT` grouped by the flight's `line` column (one group if absent), and,
/// with `by_condition`, by flight condition and heading sector (`conditions`:
/// classify_conditions(data) when the caller has it).
Evaluation error_statistics(const FlightData& data, Eigen::VectorXd error_nT,
                            bool by_condition = true,
                            const std::vector<FlightCondition>* conditions = nullptr);

/// Compensates the flight with the model and compares with the field `truth` (e.g. mag_1_c).
/// With keep_variance false the per-sample variance is used for the coverage only, not kept
/// (Evaluation::variance_nT2 empty). Throws magcomp::Error naming the file and field when `truth`
/// is missing or all NaN.
Evaluation evaluate_model(const Model& model, const FlightData& data, const std::string& truth,
                          bool keep_variance = true);

/// The model's error variance on the rows of the flights its fit did not select (other lines or
/// windows), against the field `truth`, each line's mean removed, nT²; with the count of rows
/// used. NaN (and 0) when fewer than min_rows such rows have a finite error.
std::pair<double, Eigen::Index> holdout_error_variance_nT2(
    const Model& model, const std::vector<const FlightData*>& flights, const std::string& truth,
    Eigen::Index min_rows = 600);

/// The least number of samples a score stands on: degrees of freedom once each line's mean is
/// removed (finite samples less lines).
constexpr Eigen::Index kMinDegreesOfFreedom = 10;

/// Throws magcomp::Error "SOURCE: WHAT has ..." when an evaluation stands on fewer than
/// kMinDegreesOfFreedom degrees of freedom or its rms is not finite or beyond kMaxField_nT: a
/// figure is printed only when it means something.
void require_scorable(const Evaluation& ev, const std::string& source, const std::string& what);

/// Mean-removed RMS per group, pooled (the `std_nT` above) for any residual and grouping.
double pooled_std(const Eigen::VectorXd& residual, const Eigen::VectorXd& groups);

}  // namespace magcomp
