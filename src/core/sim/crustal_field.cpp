// magcomp simulator: the crustal field's synthesis, periodic sampling and height layers.
#include "magcomp/core/sim/crustal_field.h"

#include <algorithm>
#include <cmath>
#include <complex>
#include <random>

#include "magcomp/core/geo/potential_field.h"
#include "magcomp/core/math/fft2.h"

namespace magcomp::sim {

Eigen::MatrixXd random_ground_anomaly(int n, double spacing_m, double rms_nT, double slope,
                                      unsigned seed) {
  std::mt19937_64 rng(seed * 104729ULL + 3);
  std::normal_distribution<double> normal(0.0, 1.0);
  Eigen::MatrixXcd g(n, n);
  for (Eigen::Index i = 0; i < n; ++i)  // row by row: the draws in the grid's row-major order
    for (Eigen::Index j = 0; j < n; ++j) g(i, j) = normal(rng);
  fft2(&g, false);
  const Eigen::MatrixXd k = wavenumbers(spacing_m, spacing_m, n, n).k;
  for (Eigen::Index i = 0; i < n; ++i)
    for (Eigen::Index j = 0; j < n; ++j)
      g(i, j) *= k(i, j) > 0 ? std::pow(k(i, j), -slope / 2) : 0.0;
  fft2(&g, true);
  Eigen::MatrixXd ground = g.real();
  const double rms = std::sqrt(ground.array().square().mean());
  if (rms > 0) ground *= rms_nT / rms;
  return ground;
}

double periodic_value(const Eigen::MatrixXd& grid, double spacing, double north, double east) {
  const Eigen::Index n = grid.rows();
  const double x = north / spacing, y = east / spacing;
  const double fx = std::floor(x), fy = std::floor(y);
  const double ax = x - fx, ay = y - fy;
  auto wrapi = [n](double v) {
    Eigen::Index k = static_cast<Eigen::Index>(v) % n;
    return k < 0 ? k + n : k;
  };
  const Eigen::Index i0 = wrapi(fx), i1 = wrapi(fx + 1), j0 = wrapi(fy), j1 = wrapi(fy + 1);
  return (1 - ax) * ((1 - ay) * grid(i0, j0) + ay * grid(i0, j1)) +
         ax * ((1 - ay) * grid(i1, j0) + ay * grid(i1, j1));
}

LayeredMap::LayeredMap(const Eigen::MatrixXd& ground, double spacing, double min_h, double max_h,
                       double step)
    : spacing_m_(spacing), h0_(std::max(0.0, min_h)), step_(step) {
  const int count = std::max(2, static_cast<int>(std::ceil((max_h - h0_) / step)) + 2);
  std::vector<double> heights;
  for (int k = 0; k < count; ++k) heights.push_back(h0_ + k * step);
  layers_ = upward_continue(ground, spacing, spacing, heights);
}

double LayeredMap::at(double north, double east, double height) const {
  const double u =
      std::clamp((height - h0_) / step_, 0.0, static_cast<double>(layers_.size() - 1) - 1e-9);
  const size_t k = static_cast<size_t>(u);
  const double w = u - static_cast<double>(k);
  return (1 - w) * periodic_value(layers_[k], spacing_m_, north, east) +
         w * periodic_value(layers_[k + 1], spacing_m_, north, east);
}

}  // namespace magcomp::sim
