// magcomp: the INS error dynamics of the navigation filter: the 17 Pinson error states plus an
// optional first-order Gauss-Markov (FOGM) catch-all of the measurement, as MagNav.jl models them.
//
// States (NED, radians, metres, m/s): 1-3 latitude, longitude, altitude errors; 4-6 north, east,
// down velocity errors; 7-9 tilt errors; 10 barometer aiding altitude; 11 barometer aiding
// acceleration; 12-14 accelerometer biases; 15-17 gyro biases; 18 FOGM catch-all (nT).
// The form is that of MagNav.jl's get_pinson before its v1.3.4 correction of entry (7, 3)
// (-ve^2/R^2, not -ve/R^2): the form its published test vectors were made with.
#pragma once

#include <Eigen/Core>

namespace magcomp::nav {

/// The navigation state the error dynamics are linearised about (NED frame).
struct NavPoint {
  double lat_rad = 0.0;
  double vn_mps = 0.0, ve_mps = 0.0, vd_mps = 0.0;     ///< velocity, m/s
  double fn_mps2 = 0.0, fe_mps2 = 0.0, fd_mps2 = 0.0;  ///< specific force, m/s^2
  Eigen::Matrix3d cnb = Eigen::Matrix3d::Identity();   ///< body to navigation rotation
};

/// Time constants of the error model, s.
struct ErrorModelTaus {
  double baro_s = 3600.0, acc_s = 3600.0, gyro_s = 3600.0, fogm_s = 600.0;
};

/// The continuous-time dynamics F (17 x 17, or 18 x 18 with the FOGM state), 1/s.
Eigen::MatrixXd pinson_dynamics(const NavPoint& p, const ErrorModelTaus& taus, bool fogm_state);

/// The state transition exp(F dt) over dt seconds.
Eigen::MatrixXd pinson_transition(const NavPoint& p, const ErrorModelTaus& taus, bool fogm_state,
                                  double dt_s);

}  // namespace magcomp::nav
