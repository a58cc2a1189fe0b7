// magcomp: the Pinson INS error dynamics (see pinson.h for the states).
#include "magcomp/core/nav/pinson.h"

#include <cmath>
#include <unsupported/Eigen/MatrixFunctions>

#include "magcomp/core/geo/wgs84.h"

namespace magcomp::nav {
namespace {

// Barometer-aiding gains of the third-order vertical channel (MagNav.jl's k1, k2, k3).
constexpr double kBaroK1 = 3e-2, kBaroK2 = 3e-4, kBaroK3 = 1e-6;

}  // namespace

Eigen::MatrixXd pinson_dynamics(const NavPoint& p, const ErrorModelTaus& taus, bool fogm_state) {
  const int n = fogm_state ? 18 : 17;
  const double r = kWgs84SemiMajor_m, w = kEarthRate_rps, r2 = r * r;
  const double vn = p.vn_mps, ve = p.ve_mps, vd = p.vd_mps;
  const double fn = p.fn_mps2, fe = p.fe_mps2, fd = p.fd_mps2;
  const double tan_l = std::tan(p.lat_rad), cos_l = std::cos(p.lat_rad),
               sin_l = std::sin(p.lat_rad);
  Eigen::MatrixXd f = Eigen::MatrixXd::Zero(n, n);
  // 1-based indices as in the state list.
  auto F = [&f](int i, int j) -> double& { return f(i - 1, j - 1); };
  F(1, 3) = -vn / r2;
  F(1, 4) = 1 / r;
  F(2, 1) = ve * tan_l / (r * cos_l);
  F(2, 3) = -ve / (cos_l * r2);
  F(2, 5) = 1 / (r * cos_l);
  F(3, 3) = -kBaroK1;
  F(3, 6) = -1;
  F(3, 10) = kBaroK1;
  F(4, 1) = -ve * (2 * w * cos_l + ve / (r * cos_l * cos_l));
  F(4, 3) = (ve * ve * tan_l - vn * vd) / r2;
  F(4, 4) = vd / r;
  F(4, 5) = -2 * (w * sin_l + ve * tan_l / r);
  F(4, 6) = vn / r;
  F(4, 8) = -fd;
  F(4, 9) = fe;
  F(5, 1) = 2 * w * (vn * cos_l - vd * sin_l) + vn * ve / (r * cos_l * cos_l);
  F(5, 3) = -ve * ((vn * tan_l + vd) / r2);
  F(5, 4) = 2 * w * sin_l + ve * tan_l / r;
  F(5, 5) = (vn * tan_l + vd) / r;
  F(5, 6) = 2 * w * cos_l + ve / r;
  F(5, 7) = fd;
  F(5, 9) = -fn;
  F(6, 1) = 2 * w * ve * sin_l;
  F(6, 3) = (vn * vn + ve * ve) / r2 + kBaroK2;
  F(6, 4) = -2 * vn / r;
  F(6, 5) = -2 * (w * cos_l + ve / r);
  F(6, 7) = -fe;
  F(6, 8) = fn;
  F(6, 10) = -kBaroK2;
  F(6, 11) = 1;
  F(7, 1) = -w * sin_l;
  F(7, 3) = -ve * ve / r2;  // as in the published vectors (see pinson.h)
  F(7, 5) = 1 / r;
  F(7, 8) = -w * sin_l - ve * tan_l / r;
  F(7, 9) = vn / r;
  F(8, 3) = vn / r2;
  F(8, 4) = -1 / r;
  F(8, 7) = w * sin_l + ve * tan_l / r;
  F(8, 9) = w * cos_l + ve / r;
  F(9, 1) = -w * cos_l - ve / (r * cos_l * cos_l);
  F(9, 3) = ve * tan_l / r2;
  F(9, 5) = -tan_l / r;
  F(9, 7) = -vn / r;
  F(9, 8) = -w * cos_l - ve / r;
  F(10, 10) = -1 / taus.baro_s;
  F(11, 3) = kBaroK3;
  F(11, 10) = -kBaroK3;
  for (int k = 12; k <= 14; ++k) F(k, k) = -1 / taus.acc_s;
  for (int k = 15; k <= 17; ++k) F(k, k) = -1 / taus.gyro_s;
  f.block<3, 3>(3, 11) = p.cnb;
  f.block<3, 3>(6, 14) = -p.cnb;
  if (fogm_state) F(18, 18) = -1 / taus.fogm_s;
  return f;
}

Eigen::MatrixXd pinson_transition(const NavPoint& p, const ErrorModelTaus& taus, bool fogm_state,
                                  double dt_s) {
  const Eigen::MatrixXd fdt = pinson_dynamics(p, taus, fogm_state) * dt_s;
  return fdt.exp();
}

}  // namespace magcomp::nav
