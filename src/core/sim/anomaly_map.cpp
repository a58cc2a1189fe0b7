// magcomp simulator: anomaly map synthesis and upward continuation.
#include "magcomp/core/sim/anomaly_map.h"

#include <algorithm>
#include <cmath>
#include <random>

#include "magcomp/core/math/fft2.h"

namespace magcomp::sim {

namespace {
// Wavenumber magnitude (rad/m) of FFT bin (i, j).
double wavenumber(Eigen::Index i, Eigen::Index j, Eigen::Index n, double spacing) {
  const double ki = 2 * M_PI * static_cast<double>(i <= n / 2 ? i : i - n) / (n * spacing);
  const double kj = 2 * M_PI * static_cast<double>(j <= n / 2 ? j : j - n) / (n * spacing);
  return std::hypot(ki, kj);
}
}  // namespace

AnomalyMap::AnomalyMap(Eigen::MatrixXd ground, double spacing_m)
    : n_(ground.rows()), spacing_m_(spacing_m) {
  spectrum_ = ground.cast<std::complex<double>>();
  fft2(&spectrum_, false);
}

AnomalyMap AnomalyMap::random(int n, double spacing_m, double rms_nT, double slope, unsigned seed) {
  std::mt19937_64 rng(seed * 104729ULL + 3);
  std::normal_distribution<double> normal(0.0, 1.0);
  Eigen::MatrixXcd g(n, n);
  for (Eigen::Index i = 0; i < n; ++i)  // row by row: the draws in the grid's row-major order
    for (Eigen::Index j = 0; j < n; ++j) g(i, j) = normal(rng);
  fft2(&g, false);
  for (Eigen::Index i = 0; i < n; ++i) {
    for (Eigen::Index j = 0; j < n; ++j) {
      const double k = wavenumber(i, j, n, spacing_m);
      g(i, j) *= k > 0 ? std::pow(k, -slope / 2) : 0.0;
    }
  }
  fft2(&g, true);
  Eigen::MatrixXd ground = g.real();
  const double rms = std::sqrt(ground.array().square().mean());
  if (rms > 0) ground *= rms_nT / rms;
  return AnomalyMap(ground, spacing_m);
}

Eigen::MatrixXd AnomalyMap::continued(double height_m) const {
  Eigen::MatrixXcd g = spectrum_;
  for (Eigen::Index i = 0; i < n_; ++i) {
    for (Eigen::Index j = 0; j < n_; ++j) {
      g(i, j) *= std::exp(-wavenumber(i, j, n_, spacing_m_) * height_m);
    }
  }
  fft2(&g, true);
  return g.real();
}

double AnomalyMap::sample(const Eigen::MatrixXd& grid, double spacing, double north, double east) {
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

LayeredMap::LayeredMap(const AnomalyMap& map, double min_h, double max_h, double step)
    : spacing_m_(map.spacing_m()), h0_(std::max(0.0, min_h)), step_(step) {
  const int count = std::max(2, static_cast<int>(std::ceil((max_h - h0_) / step)) + 2);
  for (int k = 0; k < count; ++k) layers_.push_back(map.continued(h0_ + k * step));
}

double LayeredMap::at(double north, double east, double height) const {
  const double u =
      std::clamp((height - h0_) / step_, 0.0, static_cast<double>(layers_.size() - 1) - 1e-9);
  const size_t k = static_cast<size_t>(u);
  const double w = u - static_cast<double>(k);
  return (1 - w) * AnomalyMap::sample(layers_[k], spacing_m_, north, east) +
         w * AnomalyMap::sample(layers_[k + 1], spacing_m_, north, east);
}

}  // namespace magcomp::sim
