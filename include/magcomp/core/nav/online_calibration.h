// magcomp: online calibration in the navigation filter. The compensation model's coefficients
// (TL and every term: all are linear in them) ride along as random-walk states, and the map is
// their reference: where the attitude and the anomaly excite a coefficient it is learned, the
// rest stay at their prior. This file holds the priors (from a fitted model, or cold: the terms
// at zero with a stated sigma each), the measurement the filter then takes (the raw anomaly and
// the model's columns), what was learned, and the model written from it.
#pragma once

#include <Eigen/Core>
#include <string>
#include <vector>

#include "magcomp/core/io/flight_data.h"
#include "magcomp/core/model/model.h"
#include "magcomp/core/nav/anomaly_map.h"
#include "magcomp/core/nav/ekf.h"

namespace magcomp::nav {

/// The cold prior sigma of a model column (its name, e.g. "induced.xy"), in the column's units:
/// permanent 200 nT, induced 500, eddy 500, any other term 50 per unit of its column.
double cold_sigma(const std::string& column_name);

/// How the coefficient states start.
struct CoefficientPriorSettings {
  bool cold = false;            ///< all at zero, cold_sigma each
  double relative_sigma = 0.2;  ///< a fitted prior's sigma: this share of each coefficient...
  double floor_share = 0.05;    ///< ...plus this share of its cold sigma, plus its fit covariance
  double walk_share_per_sqrt_h = 0.0;  ///< random walk: this share of the prior sigma per sqrt(h)
};

/// Sets `settings`' coefficient states (c0, pc0, qc_per_s) from `prior` (a fitted model with
/// the terms of `model`; ignored when cold). Throws magcomp::Error naming the model when a warm
/// prior is not fitted or its terms differ.
void set_coefficient_prior(const Model& model, const Model* prior,
                           const CoefficientPriorSettings& s, FilterSettings* settings);

/// What online calibration measures: the raw anomaly (the model's realigned scalar less the IGRF
/// and the diurnal, nT) and the model's columns at each row (N x k).
struct OnlineMeasurement {
  Eigen::VectorXd raw_anomaly_nT;
  Eigen::MatrixXd columns;
};
OnlineMeasurement online_measurement(const FlightData& flight, const Model& model);

/// One coefficient as learned: its prior and posterior mean and sigma, and the share of its
/// prior variance the flight removed (1 - sigma^2 / prior sigma^2): near 1 learned, near 0 kept at
/// its prior (unobservable on this flight's attitudes and map).
struct LearnedCoefficient {
  std::string name;
  double prior = 0, learned = 0, prior_sigma = 0, sigma = 0, variance_removed = 0;
};
std::vector<LearnedCoefficient> learned_coefficients(const Model& model,
                                                     const FilterSettings& settings,
                                                     const Eigen::VectorXd& learned,
                                                     const Eigen::MatrixXd& covariance);

/// The coefficients re-estimated over the whole flight once it is flown (a smoother of the
/// filter's estimate): least squares of the raw anomaly less the map at the filter's positions
/// on the model's columns and a constant (the aircraft's constant field, dropped), over the rows
/// whose position lies on the map. Returns the coefficients and their covariance (the
/// residual's variance times the inverse normal matrix); the filter's own estimate (filter_c,
/// filter_p) when too few rows or a singular system leave nothing better.
struct SmoothedCoefficients {
  Eigen::VectorXd coefficients;
  Eigen::MatrixXd covariance;
  Eigen::Index rows = 0;
  double residual_std_nT = NAN;
};
SmoothedCoefficients smoothed_coefficients(const OnlineMeasurement& m,
                                           const std::vector<Eigen::Index>& rows,
                                           const Eigen::VectorXd& lat_rad,
                                           const Eigen::VectorXd& lon_rad, const AnomalyMap& map,
                                           const Eigen::VectorXd& filter_c,
                                           const Eigen::MatrixXd& filter_p);

/// `model` with the learned coefficients and their covariance (the filter's), ready for
/// `evaluate` and the compensator.
Model learned_model(const Model& model, const Eigen::VectorXd& learned,
                    const Eigen::MatrixXd& covariance);

}  // namespace magcomp::nav
