// magcomp simulator: the crustal total-field anomaly the simulated aircraft flies through: a
// periodic ground grid, continued upward by geo/potential_field to a stack of heights.
#pragma once

#include <Eigen/Core>
#include <vector>

namespace magcomp::sim {

/// A random periodic square grid of the ground anomaly (n x n, nT; row = north index, col = east
/// index, spacing_m apart) with power spectrum ∝ k^-slope, scaled to rms_nT. Deterministic.
Eigen::MatrixXd random_ground_anomaly(int n, double spacing_m, double rms_nT, double slope,
                                      unsigned seed);

/// Bilinear value (nT) at (north_m, east_m) of a periodic square grid of cells spacing_m apart.
double periodic_value(const Eigen::MatrixXd& grid_nT, double spacing_m, double north_m,
                      double east_m);

/// A periodic ground grid continued upward to heights from min_height_m to max_height_m every
/// step_m, interpolated linearly in height between them.
class LayeredMap {
 public:
  LayeredMap(const Eigen::MatrixXd& ground_nT, double spacing_m, double min_height_m,
             double max_height_m, double step_m);
  /// Anomaly in nT at (north_m, east_m) and height above ground height_m.
  double at(double north_m, double east_m, double height_m) const;

 private:
  double spacing_m_, h0_, step_;
  std::vector<Eigen::MatrixXd> layers_;
};

}  // namespace magcomp::sim
