// magcomp: the local east-north-up frame (local_enu.h).
#include "magcomp/core/geo/local_enu.h"

#include <Eigen/Dense>
#include <cmath>

#include "magcomp/core/geo/wgs84.h"
#include "magcomp/core/math/constants.h"

namespace magcomp {
namespace {

constexpr double kA_m = kWgs84SemiMajor_m;
constexpr double kE2 = kWgs84Flattening * (2.0 - kWgs84Flattening);  // first eccentricity squared

}  // namespace

Eigen::Vector3d geodetic_to_ecef(double lat_deg, double lon_deg, double h_m) {
  const double lat = lat_deg * kDegToRad, lon = lon_deg * kDegToRad;
  const double s = std::sin(lat), c = std::cos(lat);
  const double n = kA_m / std::sqrt(1.0 - kE2 * s * s);
  return {(n + h_m) * c * std::cos(lon), (n + h_m) * c * std::sin(lon),
          (n * (1.0 - kE2) + h_m) * s};
}

Eigen::Vector3d ecef_to_geodetic(const Eigen::Vector3d& r) {
  // Fixed-point iteration on latitude (converges to 1e-12 rad in a few steps at aircraft heights).
  const double p = std::hypot(r.x(), r.y());
  const double lon = std::atan2(r.y(), r.x());
  double lat = std::atan2(r.z(), p * (1.0 - kE2)), h = 0.0;
  for (int i = 0; i < 8; ++i) {
    const double s = std::sin(lat);
    const double n = kA_m / std::sqrt(1.0 - kE2 * s * s);
    h = p / std::cos(lat) - n;
    lat = std::atan2(r.z(), p * (1.0 - kE2 * n / (n + h)));
  }
  return {lat * kRadToDeg, lon * kRadToDeg, h};
}

LocalEnu::LocalEnu(double lat0_deg, double lon0_deg, double h0_m)
    : origin_ecef_(geodetic_to_ecef(lat0_deg, lon0_deg, h0_m)) {
  const double lat = lat0_deg * kDegToRad, lon = lon0_deg * kDegToRad;
  const double sl = std::sin(lat), cl = std::cos(lat), so = std::sin(lon), co = std::cos(lon);
  ecef_to_enu_ << -so, co, 0.0,  //
      -sl * co, -sl * so, cl,    //
      cl * co, cl * so, sl;
}

Eigen::Vector3d LocalEnu::forward(double lat_deg, double lon_deg, double h_m) const {
  return ecef_to_enu_ * (geodetic_to_ecef(lat_deg, lon_deg, h_m) - origin_ecef_);
}

Eigen::Vector3d LocalEnu::reverse(const Eigen::Vector3d& enu) const {
  return ecef_to_geodetic(origin_ecef_ + ecef_to_enu_.transpose() * enu);
}

Eigen::Matrix3d LocalEnu::ned_to_enu() {
  Eigen::Matrix3d m;
  m << 0, 1, 0, 1, 0, 0, 0, 0, -1;
  return m;
}

}  // namespace magcomp
