// magcomp: the INS attitude between the flight files' convention (roll, pitch, yaw of
// the body FRD axes in NED, yaw clockwise from north) and REP 103's (base_link FLU in ENU), as a
// sensor_msgs/Imu orientation carries it. The bag converter writes with one, the navigator
// reads with the other (ROS-free).
#pragma once

#include <Eigen/Geometry>

namespace magcomp {

/// Roll, pitch, yaw (rad; NED/FRD) -> the orientation of base_link (FLU) in ENU.
Eigen::Quaterniond enu_orientation(double roll_rad, double pitch_rad, double yaw_rad);

/// The inverse: an ENU/FLU orientation -> (roll, pitch, yaw) rad in NED/FRD.
Eigen::Vector3d ned_attitude(const Eigen::Quaterniond& q_enu_flu);

/// A covariance of NED components (any unit squared, e.g. m^2) -> the same of ENU components.
Eigen::Matrix3d ned_to_enu_covariance(const Eigen::Matrix3d& cov_ned);

}  // namespace magcomp
