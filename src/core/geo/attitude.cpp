// magcomp: INS attitude conventions (attitude.h).
#include "magcomp/core/geo/attitude.h"

#include <algorithm>
#include <cmath>

#include "magcomp/core/geo/local_enu.h"

namespace magcomp {

Eigen::Quaterniond enu_orientation(double roll, double pitch, double yaw) {
  // yaw_enu = 90 deg - yaw (counter-clockwise from east), pitch negated (y axis to the left).
  return Eigen::AngleAxisd(M_PI / 2 - yaw, Eigen::Vector3d::UnitZ()) *
         Eigen::AngleAxisd(-pitch, Eigen::Vector3d::UnitY()) *
         Eigen::AngleAxisd(roll, Eigen::Vector3d::UnitX());
}

Eigen::Vector3d ned_attitude(const Eigen::Quaterniond& q) {
  const Eigen::Matrix3d swap = LocalEnu::ned_to_enu();  // its own inverse
  const Eigen::Matrix3d c = swap * q.toRotationMatrix() * Eigen::Vector3d(1, -1, -1).asDiagonal();
  return {std::atan2(c(2, 1), c(2, 2)), -std::asin(std::clamp(c(2, 0), -1.0, 1.0)),
          std::atan2(c(1, 0), c(0, 0))};
}

Eigen::Matrix3d ned_to_enu_covariance(const Eigen::Matrix3d& cov_ned) {
  const Eigen::Matrix3d swap = LocalEnu::ned_to_enu();
  return swap * cov_ned * swap.transpose();
}

}  // namespace magcomp
