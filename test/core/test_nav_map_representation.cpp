// The map's representation error in the filter's R, against closed forms: on a quadratic field
// the bilinear interpolation's error is exactly half the curvature times t(1-t) step^2 along each
// axis (and nothing from the cross term, which bilinear reproduces), and the part a linear update
// leaves out over a Gaussian position error of covariance P has variance 1/2 tr((C P)^2).
#include <gtest/gtest.h>

#include <Eigen/Cholesky>
#include <cmath>
#include <random>

#include "magcomp/core/nav/anomaly_map.h"

namespace magcomp::nav {
namespace {

// A quadratic field f = a y^2 + b x y + c x^2 + linear terms, y = lat - lat0, x = lon - lon0 (rad).
struct Quadratic {
  double lat0 = 0.7, lon0 = 0.1, a = 4e8, b = -2.5e8, c = 6e8, gy = 3e4, gx = -1e4;
  double operator()(double lat, double lon) const {
    const double y = lat - lat0, x = lon - lon0;
    return a * y * y + b * x * y + c * x * x + gy * y + gx * x;
  }
};

AnomalyMap quadratic_map(const Quadratic& f, double step_rad, int n) {
  AnomalyMap m;
  m.lat_rad = Eigen::VectorXd::LinSpaced(n, f.lat0 - step_rad * (n / 2),
                                         f.lat0 + step_rad * (n - 1 - n / 2));
  m.lon_rad = Eigen::VectorXd::LinSpaced(n, f.lon0 - step_rad * (n / 2),
                                         f.lon0 + step_rad * (n - 1 - n / 2));
  m.map_nT.resize(n, n);
  for (int i = 0; i < n; ++i)
    for (int j = 0; j < n; ++j) m.map_nT(i, j) = f(m.lat_rad[i], m.lon_rad[j]);
  return m;
}

TEST(MapRepresentation, TheCurvatureOfAQuadraticIsExact) {
  const Quadratic f;
  const AnomalyMap m = quadratic_map(f, 1.6e-5, 21);  // about 100 m cells
  const Eigen::Matrix2d c = m.curvature(f.lat0 + 3.3e-5, f.lon0 - 2.1e-5);
  EXPECT_NEAR(c(0, 0), 2 * f.a, 2 * f.a * 1e-6);
  EXPECT_NEAR(c(1, 1), 2 * f.c, 2 * f.c * 1e-6);
  EXPECT_NEAR(c(0, 1), f.b, std::abs(f.b) * 1e-6);
  EXPECT_NEAR(c(1, 0), f.b, std::abs(f.b) * 1e-6);
  // Off the grid's inner nodes: no curvature is claimed.
  EXPECT_EQ(m.curvature(f.lat0 + 1.0, f.lon0).norm(), 0.0);
}

TEST(MapRepresentation, TheBilinearErrorOfAQuadraticIsItsVariance) {
  const Quadratic f;
  const AnomalyMap m = quadratic_map(f, 1.6e-5, 21);
  int checked = 0;
  for (double u : {0.13, 0.5, 0.77})
    for (double v : {0.21, 0.5, 0.9}) {
      const double lat = m.lat_rad[9] + u * 1.6e-5, lon = m.lon_rad[11] + v * 1.6e-5;
      const double error = m.value(lat, lon) - f(lat, lon);
      ASSERT_GT(std::abs(error), 1e-3);
      EXPECT_NEAR(m.representation_var_nT2(lat, lon, Eigen::Matrix2d::Zero()), error * error,
                  error * error * 1e-4)
          << "u " << u << " v " << v;
      ++checked;
    }
  EXPECT_EQ(checked, 9);
  // On a node, bilinear is exact: nothing is added.
  EXPECT_NEAR(m.representation_var_nT2(m.lat_rad[10], m.lon_rad[10], Eigen::Matrix2d::Zero()), 0.0,
              1e-12);
  // Cubic convolution is exact on quadratics: the interpolation adds nothing there either.
  AnomalyMap cubic = m;
  cubic.interpolation = AnomalyMap::Interpolation::Cubic;
  const double lat = m.lat_rad[9] + 0.4e-5, lon = m.lon_rad[11] + 1.1e-5;
  EXPECT_NEAR(cubic.value(lat, lon), f(lat, lon), 1e-6);
  EXPECT_NEAR(cubic.representation_var_nT2(lat, lon, Eigen::Matrix2d::Zero()), 0.0, 1e-12);
}

TEST(MapRepresentation, TheLinearisationVarianceMatchesMonteCarlo) {
  // Position errors of 30 m and 50 m (lat, lon), correlated: the quadratic part of the field
  // over them, which a linear update leaves out, has the variance 1/2 tr((C P)^2).
  const Quadratic f;
  AnomalyMap m = quadratic_map(f, 1.6e-5, 41);
  m.interpolation = AnomalyMap::Interpolation::Cubic;  // exact on the quadratic: linearisation only
  const double sy = 30.0 / 6.371e6, sx = 50.0 / 6.371e6, rho = 0.4;
  Eigen::Matrix2d p;
  p << sy * sy, rho * sy * sx, rho * sy * sx, sx * sx;
  const double lat = f.lat0 + 2e-5, lon = f.lon0 - 3e-5;
  const double predicted = m.representation_var_nT2(lat, lon, p);
  const Eigen::Matrix2d l = p.llt().matrixL();
  const Eigen::Vector2d grad(2 * f.a * (lat - f.lat0) + f.b * (lon - f.lon0) + f.gy,
                             2 * f.c * (lon - f.lon0) + f.b * (lat - f.lat0) + f.gx);
  std::mt19937_64 rng(7);
  std::normal_distribution<double> normal(0.0, 1.0);
  const int n = 200000;
  double sum = 0, sum2 = 0;
  for (int k = 0; k < n; ++k) {
    const Eigen::Vector2d d = l * Eigen::Vector2d(normal(rng), normal(rng));
    const double left_out = f(lat + d[0], lon + d[1]) - f(lat, lon) - grad.dot(d);
    sum += left_out;
    sum2 += left_out * left_out;
  }
  const double var = sum2 / n - (sum / n) * (sum / n);
  ASSERT_GT(predicted, 1e-4);
  EXPECT_NEAR(predicted, var, 0.02 * var);  // Monte Carlo: about 0.5 % of it at 1-sigma
}

}  // namespace
}  // namespace magcomp::nav
