// magcomp: a local east-north-up frame (REP 103/105's `map`) about a geodetic origin on the
// WGS-84 ellipsoid: positions to and from metres, exactly (through Earth-centred coordinates).
#pragma once

#include <Eigen/Core>

namespace magcomp {

class LocalEnu {
 public:
  /// Origin: latitude, longitude (deg), height above the ellipsoid (m).
  LocalEnu(double lat0_deg, double lon0_deg, double h0_m);
  /// (lat deg, lon deg, h m) -> (east, north, up) m.
  Eigen::Vector3d forward(double lat_deg, double lon_deg, double h_m) const;
  /// (east, north, up) m -> (lat deg, lon deg, h m).
  Eigen::Vector3d reverse(const Eigen::Vector3d& enu_m) const;
  /// The rotation from NED at the origin to the frame's ENU axes (a vector's components).
  static Eigen::Matrix3d ned_to_enu();

 private:
  Eigen::Vector3d origin_ecef_;
  Eigen::Matrix3d ecef_to_enu_;
};

/// Geodetic (lat deg, lon deg, h m) on WGS-84 to Earth-centred Earth-fixed (m), and back.
Eigen::Vector3d geodetic_to_ecef(double lat_deg, double lon_deg, double h_m);
Eigen::Vector3d ecef_to_geodetic(const Eigen::Vector3d& ecef_m);

}  // namespace magcomp
