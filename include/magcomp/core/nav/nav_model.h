// magcomp: what the navigation filter needs besides the map: an INS track built from positions
// and attitudes, the filter's noise model from physical sigmas (MagNav.jl's create_model), and
// the errors of a solution in metres (DRMS, as MagNav.jl reports it).
#pragma once

#include <Eigen/Core>
#include <string>
#include <vector>

#include "magcomp/core/nav/ekf.h"

namespace magcomp::nav {

/// A track from positions (rad, rad, m) and attitudes (roll, pitch, yaw; rad, yaw clockwise from
/// north) sampled every dt_s: NED velocities by central differences of the positions in metres,
/// specific forces by central differences of the velocities less gravity (down), attitude as
/// body-to-NED rotations Rz(yaw) Ry(pitch) Rx(roll).
NavTrack track_from_positions(double dt_s, const Eigen::VectorXd& lat_rad,
                              const Eigen::VectorXd& lon_rad, const Eigen::VectorXd& alt_m,
                              const Eigen::VectorXd& roll_rad, const Eigen::VectorXd& pitch_rad,
                              const Eigen::VectorXd& yaw_rad);

/// Physical sigmas of the filter's model (defaults: MagNav.jl's, a navigation-grade INS).
struct ModelSigmas {
  double init_pos_m = 3.0, init_alt_m = 0.001, init_vel_mps = 0.01,
         init_att_rad = 1.7453292519943295e-4;
  double meas_var_nT2 = 9.0;
  double vrw = 0.000238;     ///< velocity random walk, m/s^2/sqrt(Hz)
  double arw = 0.000000581;  ///< angular random walk, rad/s/sqrt(Hz)
  double baro_m = 1.0, ha_m = 0.001, a_hat_mps2 = 0.01;
  double acc_mps2 = 0.000245, gyro_rps = 0.00000000727;
  double fogm_nT = 3.0;
  /// Each measurement's R also holds the map's representation error (FilterSettings).
  bool map_representation_var = false;
  ErrorModelTaus taus;
};

/// The largest settings the filter takes (their squares stay far from overflow, and nothing
/// physical lies beyond): a sigma in nT, an initial position sigma in m, a velocity sigma in m/s,
/// a time constant in s.
constexpr double kMaxSigma_nT = 1e5, kMaxPositionSigma_m = 1e6, kMaxVelocitySigma_mps = 1e3,
                 kMaxTimeConstant_s = 1e7;

/// Throws magcomp::Error "NAME: must be in (lo, hi] UNIT (got V)" unless lo < value <= hi (with
/// `lo_closed`, lo <= value). NAME is the option or parameter that set it.
void require_setting(double value, double lo, double hi, const std::string& name,
                     const std::string& unit, bool lo_closed = false);

/// P0, Qd and R of the 18-state filter at the first latitude (rad) for steps of dt_s.
FilterSettings filter_model(double dt_s, double lat1_rad, const ModelSigmas& s);

/// Horizontal position errors of a solution against the truth, m.
struct PositionErrors {
  Eigen::VectorXd north_m, east_m;
  double drms_m = 0.0;  ///< sqrt(mean(north^2 + east^2))
};

/// The errors of (lat + x1, lon + x2) against the truth; x may be empty (the track alone).
PositionErrors position_errors(const NavTrack& track, const Eigen::MatrixXd& x,
                               const Eigen::VectorXd& true_lat_rad,
                               const Eigen::VectorXd& true_lon_rad);

/// The DRMS of a covariance sequence's horizontal position (the CRLB's), m.
double covariance_drms_m(const std::vector<Eigen::MatrixXd>& p, const Eigen::VectorXd& lat_rad);

/// Latitude and longitude differences (rad) to north and east distances (m) at lat (rad).
double dlat_to_north_m(double dlat_rad, double lat_rad);
double dlon_to_east_m(double dlon_rad, double lat_rad);

}  // namespace magcomp::nav
