// magcomp: fitting a model on flights: the ridge fit of the calibration rows (calibration_rows.cpp
// selects and stacks them) and the slow stage (see fit/model_fit.h).
#include <Eigen/Dense>
#include <algorithm>
#include <cmath>
#include <cstdio>
#include <limits>
#include <sstream>

#include "magcomp/core/error.h"
#include "magcomp/core/fit/block_jackknife.h"
#include "magcomp/core/fit/model_fit.h"
#include "magcomp/core/fit/parameter_fit.h"
#include "magcomp/core/fit/slow_stage.h"
#include "magcomp/core/math/tall_products.h"
#include "magcomp/core/math/timeseries.h"
#include "magcomp/core/model/field_range.h"
#include "magcomp/core/model/model.h"
#include "magcomp/core/model/quadratic_form.h"
#include "magcomp/core/model/terms_expr.h"

namespace magcomp {

namespace {
Eigen::VectorXd ridge_from_normal(Eigen::MatrixXd g, const Eigen::VectorXd& aty, double lambda) {
  g.diagonal().array() += lambda;
  return g.ldlt().solve(aty);
}
}  // namespace

Eigen::VectorXd ridge_solve(const Eigen::MatrixXd& a, const Eigen::VectorXd& y, double lambda) {
  return ridge_from_normal(gram(a), a.transpose() * y, lambda);
}

namespace {

// Condition number of the column-normalised matrix whose Gram matrix is g.
double condition_number(Eigen::MatrixXd g) {
  if (g.cols() == 0) return 0.0;
  const Eigen::VectorXd norms = g.diagonal().cwiseMax(0.0).cwiseSqrt();
  for (Eigen::Index i = 0; i < g.rows(); ++i) {
    for (Eigen::Index j = 0; j < g.cols(); ++j) {
      const double s = norms[i] * norms[j];
      g(i, j) = s > 0 ? g(i, j) / s : 0.0;
    }
  }
  Eigen::SelfAdjointEigenSolver<Eigen::MatrixXd> es(g, Eigen::EigenvaluesOnly);
  const double lo = std::max(es.eigenvalues().minCoeff(), 0.0);
  const double hi = es.eigenvalues().maxCoeff();
  return lo > 0 ? std::sqrt(hi / lo) : std::numeric_limits<double>::infinity();
}

double std_dev(const Eigen::VectorXd& v) {
  if (v.size() < 2) return 0.0;
  const double mean = v.mean();
  return std::sqrt((v.array() - mean).square().sum() / static_cast<double>(v.size() - 1));
}

}  // namespace

Eigen::VectorXd fit_target(const Model& model, const FlightData& data) {
  Eigen::VectorXd y = aligned_scalar(model, data);
  if (model.fit.method == FitMethod::kReference) {
    if (!data.has(model.fit.reference)) {
      throw Error(data.source() + ": field '" + model.fit.reference +
                  "' (fit.reference) not found");
    }
    y -= data.column(model.fit.reference);
  }
  return y;
}

namespace {

// A model with no column the fit method can fit is refused, naming its terms.
void require_fittable_column(const Model& model) {
  const auto terms = model.make_terms();
  if (fittable_columns(model.fit.method, terms, model.slow_terms).empty()) {
    std::string list;
    for (const auto& t : terms) list += (list.empty() ? "" : ", ") + t->spec();
    throw Error("fit: the model has no column to fit (terms: [" + list + "]" +
                (model.fit.method == FitMethod::kBandpass
                     ? "; a band-pass fit cannot fit bias, and a lag "
                       "is not a column"
                     : "; a lag is not a column") +
                "): add a term, e.g. permanent, induced, eddy");
  }
}

// The calibration rows of every flight, filtered as the method wants: one block of design rows
// and targets per contiguous run of calibration samples.
struct CalibrationBlocks {
  std::vector<Eigen::MatrixXd> a;
  std::vector<Eigen::VectorXd> y;
  Eigen::Index rows = 0;
};

// The blocks of one run of a flight (or part of one) whose design `a` and target `y` are built.
void add_runs(const FitSettings& s, double dt_s, const Eigen::MatrixXd& a, const Eigen::VectorXd& y,
              const std::vector<std::pair<Eigen::Index, Eigen::Index>>& runs,
              CalibrationBlocks* blocks, FitReport* report) {
  if (runs.empty()) return;
  blocks->a.push_back(stack_runs(s, dt_s, a, runs));
  blocks->y.push_back(stack_runs(s, dt_s, y, runs).col(0));
  blocks->rows += blocks->y.back().size();
  report->segments += static_cast<int>(runs.size());
}

CalibrationBlocks calibration_blocks(const Model& model, const std::vector<TermPtr>& terms,
                                     const std::vector<const FlightData*>& flights,
                                     FitReport* report) {
  const FitSettings& s = model.fit;
  CalibrationBlocks blocks;
  // The magnetic fields of the rows the fit reads hold what a magnetometer gives.
  const std::vector<std::string> reference =
      s.reference.empty() ? std::vector<std::string>{} : std::vector<std::string>{s.reference};
  for (const FlightData* flight : flights) {
    const FlightData& data = *flight;
    const Eigen::Index margin =
        data.size() > 1 ? slice_margin(model, terms, data.dt_s()) : Eigen::Index(-1);
    if (margin < 0 || (s.lines.empty() && s.windows.empty())) {
      require_model_fields_in_range(model, data, reference);
      const Eigen::MatrixXd a = design_matrix(model, terms, data);
      const Eigen::VectorXd y = fit_target(model, data);
      add_runs(s, data.dt_s(), a, y, calibration_runs(s, data, a, y, &report->warnings), &blocks,
               report);
      continue;
    }
    // Only the calibration segments (and a margin) are built: the same rows as on the whole
    // flight, at the cost of the segments alone.
    const std::vector<Eigen::Index> selected = data.select(s.lines, s.windows);
    for (const auto& [first, last] : data.contiguous_runs(selected, 1.5 * data.dt_s())) {
      const Eigen::Index lo = std::max<Eigen::Index>(0, first - margin);
      const Eigen::Index hi = std::min(data.size(), last + 1 + margin);
      const FlightData part = data.rows(lo, hi - lo);
      require_model_fields_in_range(model, part, reference, lo);
      const Eigen::MatrixXd a = design_matrix(model, terms, part);
      const Eigen::VectorXd y = fit_target(model, part);
      std::vector<Eigen::Index> rows(static_cast<size_t>(last - first + 1));
      for (size_t k = 0; k < rows.size(); ++k) rows[k] = first - lo + static_cast<Eigen::Index>(k);
      add_runs(s, data.dt_s(), a, y,
               calibration_runs(s, part, std::move(rows), a, y, &report->warnings), &blocks,
               report);
    }
    data.drop_mapped_pages();  // this flight's segments are in the blocks: one flight at a time
  }
  return blocks;
}

// The blocks stacked into one system, keeping the columns in `keep` (no copy for one block of
// every column).
void stack_blocks(CalibrationBlocks* blocks, const std::vector<bool>& keep, Eigen::MatrixXd* a,
                  Eigen::VectorXd* y) {
  const Eigen::Index p = static_cast<Eigen::Index>(keep.size());
  const Eigen::Index fitted_cols = std::count(keep.begin(), keep.end(), true);
  if (blocks->a.size() == 1 && fitted_cols == p) {
    *a = std::move(blocks->a[0]);
    *y = std::move(blocks->y[0]);
    return;
  }
  a->resize(blocks->rows, fitted_cols);
  y->resize(blocks->rows);
  Eigen::Index r = 0;
  for (size_t b = 0; b < blocks->y.size(); ++b) {
    Eigen::Index c = 0;
    for (Eigen::Index j = 0; j < p; ++j) {
      if (keep[static_cast<size_t>(j)]) {
        a->block(r, c++, blocks->y[b].size(), 1) = blocks->a[b].col(j);
      }
    }
    y->segment(r, blocks->y[b].size()) = blocks->y[b];
    r += blocks->y[b].size();
  }
}

// A covariance of the fitted columns placed among all the model's columns (zero for the
// columns not fitted), P x P.
Eigen::MatrixXd to_all_columns(const Eigen::MatrixXd& cov_fit, const std::vector<bool>& keep) {
  const Eigen::Index p = static_cast<Eigen::Index>(keep.size());
  Eigen::MatrixXd cov = Eigen::MatrixXd::Zero(p, p);
  for (Eigen::Index i = 0, ci = 0; i < p; ++i) {
    if (!keep[static_cast<size_t>(i)]) continue;
    for (Eigen::Index j = 0, cj = 0; j < p; ++j) {
      if (!keep[static_cast<size_t>(j)]) continue;
      cov(i, j) = cov_fit(ci, cj++);
    }
    ++ci;
  }
  return cov;
}

// The coefficients' covariance (ridge sandwich, p x p with zeros for the columns not fitted),
// from the Gram matrix g of the fitted columns and the noise variance (nT^2).
Eigen::MatrixXd coefficient_covariance(const Eigen::MatrixXd& g, double lambda,
                                       double noise_variance_nT2, const std::vector<bool>& keep) {
  const Eigen::Index fitted_cols = g.rows();
  Eigen::MatrixXd gl = g;
  gl.diagonal().array() += lambda;
  const Eigen::MatrixXd inv = gl.ldlt().solve(Eigen::MatrixXd::Identity(fitted_cols, fitted_cols));
  const Eigen::MatrixXd cov_fit = noise_variance_nT2 * (inv * g * inv);
  Eigen::MatrixXd cov = to_all_columns(cov_fit, keep);
  if (!cov.allFinite()) cov.resize(0, 0);
  return cov;
}

// Warnings for the columns a band-pass fit cannot see (not those the slow stage fits), the
// unexcited ones (no energy in the filtered calibration data) and an ill-conditioned design.
void add_column_warnings(const Model& model, const Eigen::MatrixXd& g,
                         const std::vector<bool>& keep, const std::vector<Eigen::Index>& slow,
                         FitReport* report) {
  const Eigen::Index p = static_cast<Eigen::Index>(keep.size());
  const Eigen::VectorXd norms = g.diagonal().cwiseMax(0.0).cwiseSqrt();
  const double max_norm = norms.maxCoeff();
  for (Eigen::Index j = 0, c = 0; j < p; ++j) {
    if (std::find(slow.begin(), slow.end(), j) != slow.end()) continue;
    if (!keep[static_cast<size_t>(j)]) {
      report->warnings.push_back("column '" + model.column_names[static_cast<size_t>(j)] +
                                 "' is not observable by a band-pass fit; set to 0");
      continue;
    }
    if (!(norms[c] > 1e-9 * max_norm)) {
      report->warnings.push_back("column '" + model.column_names[static_cast<size_t>(j)] +
                                 "' is not excited by the calibration segments");
    }
    ++c;
  }
  if (report->condition_number > 1e6) {
    std::ostringstream w;
    w << "design matrix is ill-conditioned (condition number " << report->condition_number
      << "): the calibration segments do not excite every term; ridge lambda holds the fit";
    report->warnings.push_back(w.str());
  }
}

// The slow stage (Model::slow_terms): after the first stage (the band-pass stage, or the
// reference fit of the other columns) has set the other coefficients, the slow columns are fitted
// to the scalar minus fit.reference minus that stage's correction on the calibration segments of
// every flight and its fit.slow_lines, unfiltered, each segment's and line's mean removed. A
// reference fit's first stage reads the calibration rows unfiltered: `band_share` is then the
// other coefficients' share of the slow columns there, and the two stages together are the
// reference fit with the slow terms' size read where they move.
// `band_share` (fast x slow columns): the band-pass coefficients' share of each slow column, what
// they took of its band-passed content (the field of a bus at its steady level is that level
// times the direction cosines, which the permanent terms read): given back once the slow
// coefficients are fitted, so that the model predicts what the slow fit fitted.
void fit_slow_stage(Model& model, const std::vector<TermPtr>& terms,
                    const std::vector<const FlightData*>& flights,
                    const std::vector<Eigen::Index>& slow, const Eigen::MatrixXd& band_share,
                    FitReport* report, const std::vector<std::vector<Eigen::Index>>* slow_rows) {
  const FitSettings& s = model.fit;
  if (s.reference.empty()) {
    throw Error("fit: slow_terms need fit.reference (the field they are fitted against)");
  }
  const Eigen::Index k = static_cast<Eigen::Index>(slow.size());
  const std::vector<Eigen::Index> fast = fittable_columns(s.method, terms, model.slow_terms);
  const Eigen::Index p = static_cast<Eigen::Index>(fast.size());
  // The calibration rows of every flight, one after the other: fast columns, slow columns, and
  // the target (the scalar minus the reference minus the band-pass correction).
  std::vector<Eigen::MatrixXd> parts;
  std::vector<Eigen::VectorXd> parts_r;
  std::vector<std::pair<Eigen::Index, Eigen::Index>> runs;
  Eigen::Index rows = 0;
  for (size_t f = 0; f < flights.size(); ++f) {
    const FlightData& data = *flights[f];
    if (!data.has(s.reference)) {
      throw Error(data.source() + ": field '" + s.reference +
                  "' (fit.reference, for the slow terms) not found");
    }
    const Eigen::MatrixXd a = design_matrix(model, terms, data);
    const Eigen::VectorXd y = aligned_scalar(model, data) - data.column(s.reference);
    Eigen::VectorXd r = y;
    for (Eigen::Index j : fast) {
      if (model.coefficients[j] != 0.0) r -= a.col(j) * model.coefficients[j];
    }
    const std::vector<Eigen::Index>* extra = slow_rows ? &(*slow_rows)[f] : nullptr;
    for (const auto& [first, last] : slow_stage_runs(s, data, a, y, extra)) {
      const Eigen::Index len = last - first + 1;
      Eigen::MatrixXd part(len, p + k);
      for (Eigen::Index c = 0; c < p; ++c)
        part.col(c) = a.col(fast[static_cast<size_t>(c)]).segment(first, len);
      for (Eigen::Index c = 0; c < k; ++c)
        part.col(p + c) = a.col(slow[static_cast<size_t>(c)]).segment(first, len);
      parts.push_back(std::move(part));
      parts_r.push_back(r.segment(first, len));
      runs.emplace_back(rows, rows + len - 1);
      rows += len;
    }
    data.drop_mapped_pages();
  }
  if (rows < 2 * (p + k)) {
    throw Error("fit: only " + std::to_string(rows) + " calibration samples for " +
                std::to_string(k) + " slow coefficients");
  }
  Eigen::MatrixXd all(rows, p + k);
  Eigen::VectorXd r_all(rows);
  for (size_t b = 0; b < parts.size(); ++b) {
    all.middleRows(runs[b].first, parts[b].rows()) = parts[b];
    r_all.segment(runs[b].first, parts_r[b].size()) = parts_r[b];
  }
  const SlowStage stage(all.leftCols(p), r_all, runs, s.lambda);
  double rss = 0;
  const Eigen::VectorXd c = stage.fit(all.rightCols(k), &rss);
  if (!c.allFinite()) {
    throw Error("fit: the slow terms' solution is not finite (fit.lambda " +
                std::to_string(s.lambda) + "); nothing written");
  }
  for (Eigen::Index j = 0; j < k; ++j) model.coefficients[slow[static_cast<size_t>(j)]] = c[j];
  if (band_share.rows() == p && band_share.cols() == k) {
    const Eigen::VectorXd back = band_share * c;
    for (Eigen::Index j = 0; j < p && back.allFinite(); ++j)
      model.coefficients[fast[static_cast<size_t>(j)]] -= back[j];
  }
  char buf[256];
  std::snprintf(buf, sizeof(buf),
                "%lld slow column(s) fitted against %s on %lld samples of the calibration "
                "segments%s (segment means and the other columns' span removed): residual "
                "std %.3g nT",
                static_cast<long long>(k), s.reference.c_str(),
                static_cast<long long>(stage.rows()),
                slow_rows              ? " and the rows given"
                : s.slow_lines.empty() ? ""
                                       : " and fit.slow_lines",
                std::sqrt(rss / static_cast<double>(std::max<Eigen::Index>(stage.rows(), 1))));
  report->estimates.push_back(buf);
}

}  // namespace

void fit_model(Model& model, const std::vector<const FlightData*>& flights) {
  fit_model(model, flights, nullptr);
}

namespace {

void fit_model_once(Model& model, const std::vector<const FlightData*>& flights,
                    const std::vector<std::vector<Eigen::Index>>* slow_rows) {
  if (flights.empty()) throw Error("fit: no flight given");
  if (slow_rows && slow_rows->size() != flights.size())
    throw Error("fit: slow rows given for " + std::to_string(slow_rows->size()) + " flights, not " +
                std::to_string(flights.size()));
  require_fittable_column(model);
  const std::vector<std::string> estimates = estimate_free_parameters(model, flights);
  const FitSettings& s = model.fit;
  const auto terms = model.make_terms();
  Eigen::Index columns = 0;
  for (const auto& t : terms) columns += t->columns();
  std::vector<bool> keep(static_cast<size_t>(columns), false);  // columns the method can fit
  for (Eigen::Index c : fittable_columns(model.fit.method, terms, model.slow_terms))
    keep[static_cast<size_t>(c)] = true;
  std::string sources;
  for (const FlightData* flight : flights) {
    sources += (sources.empty() ? "" : ",") + flight->source();
  }
  FitReport report;
  CalibrationBlocks blocks = calibration_blocks(model, terms, flights, &report);
  const Eigen::Index rows = blocks.rows;
  const Eigen::Index p = static_cast<Eigen::Index>(keep.size());
  const Eigen::Index fitted_cols = std::count(keep.begin(), keep.end(), true);
  if (rows == 0) {
    throw Error(
        "fit: the calibration selection (fit.lines / fit.windows) holds no usable sample in " +
        sources);
  }
  if (rows < 2 * fitted_cols) {
    throw Error("fit: only " + std::to_string(rows) + " usable samples for " +
                std::to_string(fitted_cols) + " coefficients in " + sources);
  }
  const std::vector<Eigen::Index> slow = slow_columns(terms, model.slow_terms);
  Eigen::MatrixXd a_slow;  // the slow columns as the band-pass stage sees them
  if (!slow.empty()) {
    std::vector<bool> keep_slow(keep.size(), false);
    for (Eigen::Index c : slow) keep_slow[static_cast<size_t>(c)] = true;
    Eigen::VectorXd unused;
    stack_blocks(&blocks, keep_slow, &a_slow, &unused);
  }
  Eigen::MatrixXd a;
  Eigen::VectorXd y;
  stack_blocks(&blocks, keep, &a, &y);
  if (!a.allFinite() || !y.allFinite()) {
    throw Error("fit: the filtered calibration data hold NaN or Inf (fit.band_hz [" +
                std::to_string(s.band_low_hz) + ", " + std::to_string(s.band_high_hz) +
                "] Hz against the sample rate, or non-finite inputs) in " + sources);
  }
  const Eigen::MatrixXd g = gram(a);
  const Eigen::VectorXd c_fit = ridge_from_normal(g, a.transpose() * y, s.lambda);
  if (!c_fit.allFinite()) {
    throw Error("fit: the solution is not finite (fit.lambda " + std::to_string(s.lambda) +
                ", condition number of the data too high) in " + sources + "; nothing written");
  }
  model.coefficients = Eigen::VectorXd::Zero(p);
  for (Eigen::Index j = 0, c = 0; j < p; ++j) {
    if (keep[static_cast<size_t>(j)]) model.coefficients[j] = c_fit[c++];
  }
  model.column_names = model.make_column_names();
  report.samples = rows;
  report.condition_number = condition_number(g);
  const Eigen::VectorXd residual = y - a * c_fit;
  report.residual_std_nT = std_dev(residual);
  report.estimates = estimates;
  const double dof = static_cast<double>(std::max<Eigen::Index>(rows - fitted_cols, 1));
  report.noise_variance_nT2 = residual.squaredNorm() / dof;
  if (!std::isfinite(report.residual_std_nT) || !std::isfinite(report.noise_variance_nT2)) {
    char buf[160];
    std::snprintf(buf, sizeof buf, "(largest |value|: target %.3g nT, columns %.3g)",
                  y.cwiseAbs().maxCoeff(), a.cwiseAbs().maxCoeff());
    throw Error("fit: the residual of " + model.scalar +
                " is too large to square: its values or the columns' are beyond any magnetic "
                "field " +
                buf + " in " + sources + "; nothing written");
  }
  report.coefficient_covariance =
      coefficient_covariance(g, s.lambda, report.noise_variance_nT2, keep);
  add_column_warnings(model, g, keep, slow, &report);
  if (!slow.empty()) {
    // The band-pass coefficients' share of each slow column's band-passed content (NaN-free
    // columns only: a column the band cannot read is given nothing back).
    Eigen::MatrixXd band_share;
    if (a_slow.allFinite()) {
      Eigen::MatrixXd gl = g;
      gl.diagonal().array() += s.lambda;
      band_share = gl.ldlt().solve(a.transpose() * a_slow);
    }
    fit_slow_stage(model, terms, flights, slow, band_share, &report, slow_rows);
  }
  model.report = report;
}
}  // namespace

void fit_model(Model& model, const std::vector<const FlightData*>& flights,
               const std::vector<std::vector<Eigen::Index>>* slow_rows) {
  // The lines no flight flies, read once whatever the passes below (said first in the report).
  const std::vector<std::string> unflown = lines_flown_nowhere(model.fit, flights);
  const auto say_unflown = [&] {
    model.report.warnings.insert(model.report.warnings.begin(), unflown.begin(), unflown.end());
  };
  const bool norm = std::find(model.terms.begin(), model.terms.end(), "norm") != model.terms.end();
  if (!norm) {
    fit_model_once(model, flights, slow_rows);
    say_unflown();
    return;
  }
  // The exact norm's column is built from the model's own TL coefficients: fit, build it again
  // from what the fit gave, and fit again until the coefficients settle (the remainder is second
  // order in the aircraft's field, so a pass or two). An unfitted model starts with the column
  // at zero, i.e. from plain TL.
  constexpr int kMaxPasses = 8;
  constexpr double kSettled = 1e-4;  // largest change of a coefficient, nT per column unit
  if (!model.fitted()) fit_model_once(model, flights, slow_rows);
  for (int pass = 0; pass < kMaxPasses; ++pass) {
    const Eigen::VectorXd before = model.coefficients;
    const std::vector<std::string> names = model.column_names;
    fit_model_once(model, flights, slow_rows);
    if (names == model.column_names && before.size() == model.coefficients.size() &&
        (model.coefficients - before).cwiseAbs().maxCoeff() <= kSettled)
      break;
  }
  say_unflown();
}

Eigen::MatrixXd coefficient_jackknife_covariance(const Model& model,
                                                 const std::vector<const FlightData*>& flights,
                                                 int groups) {
  const Eigen::Index p = model.coefficients.size();
  if (!model.fitted() || flights.empty() || groups < 2) return Eigen::MatrixXd();
  const auto terms = model.make_terms();
  std::vector<bool> keep(static_cast<size_t>(p), false);
  for (Eigen::Index c : fittable_columns(model.fit.method, terms, model.slow_terms))
    if (c < p) keep[static_cast<size_t>(c)] = true;
  FitReport report;
  CalibrationBlocks blocks = calibration_blocks(model, terms, flights, &report);
  Eigen::MatrixXd a;
  Eigen::VectorXd y;
  stack_blocks(&blocks, keep, &a, &y);
  const Eigen::Index rows = a.rows(), k = a.cols();
  if (rows < 2 * static_cast<Eigen::Index>(groups) * std::max<Eigen::Index>(k, 1) ||
      !a.allFinite() || !y.allFinite())
    return Eigen::MatrixXd();
  // The fit without each group of rows in turn, and the spread of those fits.
  const double lambda = model.fit.lambda;
  const Jackknife j =
      block_jackknife(a, y, groups, [lambda](const Eigen::MatrixXd& g, const Eigen::VectorXd& b) {
        return ridge_from_normal(g, b, lambda);
      });
  if (!j.replicates.allFinite()) return Eigen::MatrixXd();
  const Eigen::MatrixXd cov_fit = j.covariance();
  Eigen::MatrixXd cov = to_all_columns(cov_fit, keep);
  return cov;
}

}  // namespace magcomp
