// magcomp: online calibration in the navigation filter (online_calibration.h).
#include "magcomp/core/nav/online_calibration.h"

#include <Eigen/Dense>
#include <algorithm>
#include <cmath>

#include "magcomp/core/error.h"
#include "magcomp/core/nav/flight_navigation.h"

namespace magcomp::nav {

double cold_sigma(const std::string& name) {
  const std::string family = name.substr(0, name.find('.'));
  if (family == "permanent") return 200.0;
  if (family == "induced" || family == "eddy") return 500.0;
  return 50.0;
}

void set_coefficient_prior(const Model& model, const Model* prior,
                           const CoefficientPriorSettings& s, FilterSettings* settings) {
  const std::vector<std::string> names = model.make_column_names();
  const auto k = static_cast<Eigen::Index>(names.size());
  if (k == 0) throw Error("online calibration: the model has no coefficient to learn");
  Eigen::VectorXd cold(k);
  for (Eigen::Index j = 0; j < k; ++j) cold[j] = cold_sigma(names[static_cast<size_t>(j)]);
  settings->c0 = Eigen::VectorXd::Zero(k);
  settings->pc0 = Eigen::MatrixXd(cold.array().square().matrix().asDiagonal());
  if (!s.cold) {
    if (!prior || !prior->fitted())
      throw Error(
          "online calibration: the prior model has no coefficients (calibrate it, or "
          "start cold)");
    if (prior->make_column_names() != names)
      throw Error("online calibration: the prior model's terms differ from the model's");
    settings->c0 = prior->coefficients;
    Eigen::VectorXd var =
        (s.relative_sigma * prior->coefficients.array().abs() + s.floor_share * cold.array())
            .square();
    Eigen::MatrixXd p0 = var.asDiagonal();
    const Eigen::MatrixXd& fit = prior->report.coefficient_covariance;
    if (fit.rows() == k && fit.cols() == k && fit.allFinite()) p0 += fit;
    settings->pc0 = p0;
  }
  // The walk: walk_share of each prior sigma per sqrt(hour).
  settings->qc_per_s =
      (s.walk_share_per_sqrt_h * settings->pc0.diagonal().cwiseSqrt()).array().square().matrix() /
      3600.0;
}

OnlineMeasurement online_measurement(const FlightData& f, const Model& model) {
  OnlineMeasurement m;
  m.raw_anomaly_nT = flight_anomaly_nT(f, aligned_scalar(model, f));
  m.columns = design_matrix(model, f);
  return m;
}

std::vector<LearnedCoefficient> learned_coefficients(const Model& model,
                                                     const FilterSettings& settings,
                                                     const Eigen::VectorXd& learned,
                                                     const Eigen::MatrixXd& covariance) {
  const std::vector<std::string> names = model.make_column_names();
  std::vector<LearnedCoefficient> out;
  for (size_t j = 0; j < names.size(); ++j) {
    const auto i = static_cast<Eigen::Index>(j);
    LearnedCoefficient c;
    c.name = names[j];
    c.prior = settings.c0[i];
    c.learned = learned[i];
    c.prior_sigma = std::sqrt(settings.pc0(i, i));
    c.sigma = std::sqrt(std::max(0.0, covariance(i, i)));
    c.variance_removed = 1.0 - (c.sigma * c.sigma) / (c.prior_sigma * c.prior_sigma);
    out.push_back(c);
  }
  return out;
}

SmoothedCoefficients smoothed_coefficients(const OnlineMeasurement& m,
                                           const std::vector<Eigen::Index>& rows,
                                           const Eigen::VectorXd& lat_rad,
                                           const Eigen::VectorXd& lon_rad, const AnomalyMap& map,
                                           const Eigen::VectorXd& filter_c,
                                           const Eigen::MatrixXd& filter_p) {
  const Eigen::Index k = m.columns.cols();
  Eigen::MatrixXd g = Eigen::MatrixXd::Zero(k + 1, k + 1);
  Eigen::VectorXd b = Eigen::VectorXd::Zero(k + 1);
  Eigen::VectorXd x(k + 1);
  std::vector<Eigen::Index> used;
  for (size_t j = 0; j < rows.size(); ++j) {
    const Eigen::Index i = rows[j];
    if (!std::isfinite(lat_rad[static_cast<Eigen::Index>(j)]) ||
        !map.covers(lat_rad[static_cast<Eigen::Index>(j)], lon_rad[static_cast<Eigen::Index>(j)]))
      continue;
    const double y = m.raw_anomaly_nT[i] - map.value(lat_rad[static_cast<Eigen::Index>(j)],
                                                     lon_rad[static_cast<Eigen::Index>(j)]);
    x.head(k) = m.columns.row(i).transpose();
    x[k] = 1.0;
    if (!std::isfinite(y) || !x.allFinite()) continue;
    g.selfadjointView<Eigen::Lower>().rankUpdate(x);
    b += x * y;
    used.push_back(j);
  }
  SmoothedCoefficients out;
  out.rows = static_cast<Eigen::Index>(used.size());
  if (out.rows <= 2 * (k + 1)) {  // too few: the filter's own estimate
    out.coefficients = filter_c;
    out.covariance = filter_p;
    return out;
  }
  g = g.selfadjointView<Eigen::Lower>();
  const Eigen::LDLT<Eigen::MatrixXd> plain(g + 1e-9 * Eigen::MatrixXd::Identity(k + 1, k + 1));
  const Eigen::VectorXd c0 = plain.solve(b);
  double ss = 0;
  for (size_t j : used) {
    const Eigen::Index i = rows[j];
    x.head(k) = m.columns.row(i).transpose();
    x[k] = 1.0;
    const double e =
        m.raw_anomaly_nT[i] -
        map.value(lat_rad[static_cast<Eigen::Index>(j)], lon_rad[static_cast<Eigen::Index>(j)]) -
        x.dot(c0);
    ss += e * e;
  }
  const double var = std::max(ss / static_cast<double>(out.rows - k - 1), 1e-12);
  out.coefficients = c0.head(k);
  out.covariance = var * plain.solve(Eigen::MatrixXd::Identity(k + 1, k + 1)).topLeftCorner(k, k);
  out.residual_std_nT = std::sqrt(var);
  if (!out.coefficients.allFinite() || !out.covariance.allFinite()) {
    out.coefficients = filter_c;
    out.covariance = filter_p;
  }
  return out;
}

Model learned_model(const Model& model, const Eigen::VectorXd& learned,
                    const Eigen::MatrixXd& covariance) {
  Model m = model;
  m.coefficients = learned;
  m.column_names = m.make_column_names();
  m.report.coefficient_covariance = covariance;
  return m;
}

}  // namespace magcomp::nav
