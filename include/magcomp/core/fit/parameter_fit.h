// magcomp: profile least squares for the nonlinear parameters of terms (time constants, delays,
// exponents): the fit rows, a ridge solve that reuses the fixed columns' normal equations, and the
// coarse-scan + golden-section search.
#pragma once

#include <Eigen/Core>
#include <functional>
#include <string>
#include <utility>
#include <vector>

#include "magcomp/core/model/model.h"
#include "magcomp/core/model/signal.h"

namespace magcomp {

/// The rows a model's fit uses on some flights: each flight's calibration runs (fit.lines /
/// fit.windows, NaN rows dropped), band-passed and trimmed for a bandpass fit.
class FitRowSet {
 public:
  /// Runs are chosen with the model's terms as given (`model` must have no free parameter).
  FitRowSet(const Model& model, const std::vector<const FlightData*>& flights,
            std::vector<std::string>* warnings);
  /// Stacks per-flight columns (N_f x k each, one matrix per flight) into fit rows. NaN in a
  /// candidate's columns is taken as 0.
  Eigen::MatrixXd stack(const std::vector<Eigen::MatrixXd>& per_flight) const;
  /// The stacked target (scalar, or scalar - reference), nT.
  const Eigen::VectorXd& y() const { return y_; }
  Eigen::Index rows() const { return y_.size(); }
  int segments() const { return segments_; }

 private:
  FitSettings fit_;
  std::vector<const FlightData*> flights_;
  std::vector<std::vector<std::pair<Eigen::Index, Eigen::Index>>> runs_;
  Eigen::VectorXd y_;
  int segments_ = 0;
};

/// The ridge solution of normal equations G c = b (G = X'X, b = X'y, in the columns' units):
/// (G + lambda I) c = b on the column-normalised system, directions below 1e-10 of the largest
/// eigenvalue dropped (exactly collinear columns share their coefficients).
Eigen::VectorXd ridge_normal_solve(const Eigen::MatrixXd& g, const Eigen::VectorXd& b,
                                   double lambda);

/// Ridge least squares of y on [base, candidate] with the base's normal equations formed once.
class RidgeProfile {
 public:
  RidgeProfile(const Eigen::MatrixXd& base, const Eigen::VectorXd& y, double lambda);
  /// Coefficients [base; candidate] and the residual sum of squares (nT²) in *rss.
  Eigen::VectorXd solve(const Eigen::MatrixXd& candidate, double* rss) const;
  Eigen::Index base_columns() const { return g00_.cols(); }

 private:
  const Eigen::MatrixXd& base_;
  const Eigen::VectorXd& y_;
  Eigen::MatrixXd g00_;
  Eigen::VectorXd b0_;
  double yy_ = 0.0, lambda_ = 0.0;
};

/// The values a free parameter of this kind is scanned over, for a flight sampled every dt_s and
/// lasting span_s (time constants on a geometric grid, delays on a uniform one). The parameters
/// in the signal's unit are scanned over its range (signal_lo, signal_lo + signal_scale): a
/// play(?) half-width over 2 % to 50 % of the spread, a sat(?) level over 0.1 to 3 times the
/// largest |value|, a ramp(?) hinge (or a step(?) threshold) over the range's 5 % to 95 % (steps
/// of 5 %); calibrate and diagnose scan a step's threshold over the signal's quantiles instead
/// (scan_threshold()).
std::vector<double> parameter_grid(TransformKind kind, double dt_s, double span_s,
                                   double signal_scale = 0.0, double signal_lo = 0.0);

/// The longest time constant a low-pass or high-pass is scanned up to on a flight sampled every
/// dt_s and lasting span_s (the top of parameter_grid's scan: a third of the flight, at most
/// 3000 s), s. 0 when the scan is empty.
double longest_scanned_time_constant_s(double dt_s, double span_s);

/// Whether the time constant tau_s (s) sits at the top of such a scan, top_s (within 1 %): the
/// flight cannot tell it from a slower one, so it stands for a drift, not an estimated response.
bool at_longest_scanned_time_constant(double tau_s, double top_s);

/// Whether a free parameter of this kind is in the signal's unit (needs signal_range()).
bool in_signal_units(TransformKind kind);

/// The range of a signal's sources on a flight (their product's 5th and 95th percentiles); both
/// 0 when it cannot be formed.
struct SignalRange {
  double lo = 0.0, hi = 0.0;
};
SignalRange signal_range(const SignalExpr& signal, const FlightData& data);

/// signal_range()'s spread (hi - lo); 0 when it cannot be formed.
double signal_scale(const SignalExpr& signal, const FlightData& data);

/// Minimises objective(value) over the grid, then by golden section between the best value's
/// neighbours (in log space for time constants). Returns the minimiser rounded to 3 significant
/// digits and the objective there in *best.
double scan_parameter(TransformKind kind, const std::vector<double>& grid,
                      const std::function<double(double)>& objective, double* best = nullptr);

/// The product of a signal's sources on a flight, per row; the sources `data` does not have are
/// left out, and *missing (when given) is their count.
Eigen::VectorXd signal_sources_product(const SignalExpr& signal, const FlightData& data,
                                       size_t* missing = nullptr);

/// The finite values of a signal's sources on a flight (their product), sorted; empty when fewer
/// than 20. A step's threshold is scanned over them (scan_threshold()).
std::vector<double> signal_values_sorted(const SignalExpr& signal, const FlightData& data);

/// Minimises objective(threshold) over the signal's quantiles (sorted_values, in the signal's
/// unit): a grid of quantile levels from 2 % to 98 %, then golden section in the quantile level
/// between the best level's neighbours. A switched load's error changes with every sample on the
/// wrong side of its threshold, so the threshold is sought where the samples are: a relay whose
/// control sits in the noise of an idle channel is found to the sample, not skipped by an even
/// grid over the channel's range. Returns the middle of the gap between the two values of
/// sorted_values around the best threshold, written with the fewest significant digits (3 at
/// least) that leave every value on the side of it it was on, and the objective there in *best.
/// Throws magcomp::Error when sorted_values is empty.
double scan_threshold(const std::vector<double>& sorted_values,
                      const std::function<double(double)>& objective, double* best = nullptr);

/// The threshold (in the signal's unit) that splits sorted_values as x does, written as
/// scan_threshold() writes it: the middle of the gap between the two values around x, with the
/// fewest significant digits (3 at least) that leave every value on its side; x itself when no
/// value lies above or below it.
double written_threshold(const std::vector<double>& sorted_values, double x);

/// Estimates every free parameter ('?') of the model's terms by profile least squares on the fit
/// rows of `flights`: each in turn, the others held (two sweeps when there are several). Replaces
/// the specs in model.terms by their numbers and returns one line per parameter for the report.
/// Throws magcomp::Error when no fit row holds the term.
std::vector<std::string> estimate_free_parameters(Model& model,
                                                  const std::vector<const FlightData*>& flights);

}  // namespace magcomp
