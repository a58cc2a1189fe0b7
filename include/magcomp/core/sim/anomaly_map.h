// magcomp simulator: a crustal total-field anomaly map, upward-continued by FFT.
#pragma once

#include <Eigen/Core>
#include <complex>
#include <vector>

namespace magcomp::sim {

/// A periodic square grid of the total-field anomaly (nT), x = north, y = east, spacing in m.
class AnomalyMap {
 public:
  /// A random map at ground level with power spectrum ∝ k^-slope, scaled to rms_nT. Deterministic.
  static AnomalyMap random(int n, double spacing_m, double rms_nT, double slope, unsigned seed);
  /// A map from given ground values (row = north index, col = east index).
  AnomalyMap(Eigen::MatrixXd ground_nT, double spacing_m);

  /// The map continued upward by height_m >= 0 (multiplies the spectrum by exp(-|k| h)).
  Eigen::MatrixXd continued(double height_m) const;
  /// Bilinear value at (north_m, east_m) of a grid (periodic).
  static double sample(const Eigen::MatrixXd& grid, double spacing_m, double north_m,
                       double east_m);

  double spacing_m() const { return spacing_m_; }
  int size() const { return static_cast<int>(n_); }

 private:
  Eigen::Index n_ = 0;
  double spacing_m_ = 100.0;
  Eigen::MatrixXcd spectrum_;  // n x n, the ground values' 2-D FFT (math/fft2.h)
};

/// Samples a map at several heights above ground and interpolates linearly in height.
class LayeredMap {
 public:
  LayeredMap(const AnomalyMap& map, double min_height_m, double max_height_m, double step_m);
  /// Anomaly in nT at (north_m, east_m) and height above ground height_m.
  double at(double north_m, double east_m, double height_m) const;

 private:
  double spacing_m_, h0_, step_;
  std::vector<Eigen::MatrixXd> layers_;
};

}  // namespace magcomp::sim
