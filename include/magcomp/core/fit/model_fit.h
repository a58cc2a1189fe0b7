// magcomp: fitting a model's coefficients: the calibration runs a fit reads, their band-pass and
// stacking, the target, the ridge solve and the fit itself (its report in Model::report).
#pragma once

#include <Eigen/Core>
#include <string>
#include <utility>
#include <vector>

#include "magcomp/core/io/flight_data.h"
#include "magcomp/core/model/model.h"

namespace magcomp {

/// Fits the model's coefficients on `flights` according to model.fit. Free parameters (?) are
/// estimated first (parameter_fit.h) and written into model.terms as numbers. Throws
/// magcomp::Error when the selection is empty or too short. Stores coefficients, column names and
/// the report.
void fit_model(Model& model, const std::vector<const FlightData*>& flights);

/// The same, with the slow stage fitted on the calibration rows and `slow_rows` (per flight,
/// indices into it) in place of fit.slow_lines: diagnose's cross-fit, which sizes the slow terms
/// on one half of the held-out rows to score them on the other.
void fit_model(Model& model, const std::vector<const FlightData*>& flights,
               const std::vector<std::vector<Eigen::Index>>* slow_rows);

/// Contiguous calibration runs [first, last] of `data` selected by the fit settings (all samples
/// for a reference fit without lines or windows), skipping rows where `a` or `y` is not finite, and
/// dropping runs too short for the band-pass and trim (noted in `warnings`).
std::vector<std::pair<Eigen::Index, Eigen::Index>> calibration_runs(
    const FitSettings& fit, const FlightData& data, const Eigen::MatrixXd& a,
    const Eigen::VectorXd& y, std::vector<std::string>* warnings);

/// The same for the samples `selected` (sorted indices into `data`) instead of the fit's lines
/// and windows.
std::vector<std::pair<Eigen::Index, Eigen::Index>> calibration_runs(
    const FitSettings& fit, const FlightData& data, std::vector<Eigen::Index> selected,
    const Eigen::MatrixXd& a, const Eigen::VectorXd& y, std::vector<std::string>* warnings);

/// The runs [first, last] the slow stage (Model::slow_terms) is fitted on: the calibration runs,
/// then the runs of `rows` (indices into `data`; null: the rows of fit.slow_lines), each within
/// one line, calibration rows left to those, each run's mean removed by the stage.
std::vector<std::pair<Eigen::Index, Eigen::Index>> slow_stage_runs(
    const FitSettings& fit, const FlightData& data, const Eigen::MatrixXd& a,
    const Eigen::VectorXd& y, const std::vector<Eigen::Index>* rows = nullptr);

/// The lines of fit.lines and fit.slow_lines that none of `flights` flies, each as a warning
/// naming the key, the line and the flights: a mistyped line number leaves the fit on fewer rows
/// than the model file lists (fit_model puts them first in FitReport::warnings).
std::vector<std::string> lines_flown_nowhere(const FitSettings& fit,
                                             const std::vector<const FlightData*>& flights);

/// The rows of `x` in each run, band-passed and trimmed (bandpass method) or as they are
/// (reference method), stacked. dt_s is the sample period.
Eigen::MatrixXd stack_runs(const FitSettings& fit, double dt_s, const Eigen::MatrixXd& x,
                           const std::vector<std::pair<Eigen::Index, Eigen::Index>>& runs);

/// The regression target of a fit: the scalar field (bandpass) or scalar - reference (nT).
Eigen::VectorXd fit_target(const Model& model, const FlightData& data);

/// The covariance of a fitted model's band-pass (or reference) stage coefficients by a
/// delete-one-group jackknife: the calibration rows of `flights` (the fit's, in time order) cut
/// into `groups` contiguous blocks, the fit redone without each block, and (G-1)/G times the
/// spread of those fits. Unlike FitReport::coefficient_covariance it holds when the residual is
/// correlated in time (a band-passed error, a misfit that follows the maneuvers) and when a
/// column is excited by a few events only (a current switched twice). P x P in column order, in
/// nT² per (column unit)², zero for the columns the stage does not fit (the slow stage's);
/// empty when the rows are too few (under 2 x groups x columns) or the model is not fitted.
Eigen::MatrixXd coefficient_jackknife_covariance(const Model& model,
                                                 const std::vector<const FlightData*>& flights,
                                                 int groups = 20);

/// Ridge least squares (A'A + lambda I) c = A'y, as MagNav.jl's linreg.
Eigen::VectorXd ridge_solve(const Eigen::MatrixXd& a, const Eigen::VectorXd& y, double lambda);

}  // namespace magcomp
