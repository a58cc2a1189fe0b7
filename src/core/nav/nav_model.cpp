// magcomp: INS tracks from positions, the filter's noise model, position errors in metres.
#include "magcomp/core/nav/nav_model.h"

#include <cmath>

#include "magcomp/core/error.h"
#include "magcomp/core/math/constants.h"

namespace magcomp::nav {
namespace {

constexpr double kEarthRadius_m = 6378137.0;  // MagNav.jl's r_earth and e_earth
constexpr double kEccentricity = 0.0818191908426;

// Central difference per step (one-sided at the ends), divided by dt.
Eigen::VectorXd rate(const Eigen::VectorXd& v, double dt) {
  const Eigen::Index n = v.size();
  Eigen::VectorXd d(n);
  if (n < 2) return Eigen::VectorXd::Zero(n);
  d[0] = (v[1] - v[0]) / dt;
  d[n - 1] = (v[n - 1] - v[n - 2]) / dt;
  for (Eigen::Index i = 1; i + 1 < n; ++i) d[i] = (v[i + 1] - v[i - 1]) / (2 * dt);
  return d;
}

}  // namespace

double dlat_to_north_m(double dlat, double lat) {
  return dlat / std::sqrt(1 - std::pow(kEccentricity * std::sin(lat), 2)) * kEarthRadius_m;
}

double dlon_to_east_m(double dlon, double lat) {
  return dlon / std::sqrt(1 - std::pow(kEccentricity * std::sin(lat), 2)) * kEarthRadius_m *
         std::cos(lat);
}

NavTrack track_from_positions(double dt_s, const Eigen::VectorXd& lat, const Eigen::VectorXd& lon,
                              const Eigen::VectorXd& alt, const Eigen::VectorXd& roll,
                              const Eigen::VectorXd& pitch, const Eigen::VectorXd& yaw) {
  const Eigen::Index n = lat.size();
  if (lon.size() != n || alt.size() != n || roll.size() != n || pitch.size() != n ||
      yaw.size() != n)
    throw Error("navigation track: positions and attitudes differ in length");
  if (!(dt_s > 0)) throw Error("navigation track: the time step must be > 0 s");
  NavTrack t;
  t.dt_s = dt_s;
  t.lat_rad = lat;
  t.lon_rad = lon;
  t.alt_m = alt;
  Eigen::VectorXd north(n), east(n);
  for (Eigen::Index i = 0; i < n; ++i) {
    north[i] = dlat_to_north_m(lat[i] - lat[0], lat[i]);
    east[i] = dlon_to_east_m(lon[i] - lon[0], lat[i]);
  }
  t.vn_mps = rate(north, dt_s);
  t.ve_mps = rate(east, dt_s);
  t.vd_mps = -rate(alt, dt_s);
  t.fn_mps2 = rate(t.vn_mps, dt_s);
  t.fe_mps2 = rate(t.ve_mps, dt_s);
  t.fd_mps2 = rate(t.vd_mps, dt_s).array() - kStandardGravity_mps2;
  for (Eigen::Index i = 0; i < n; ++i) {
    const double cr = std::cos(roll[i]), sr = std::sin(roll[i]), cp = std::cos(pitch[i]),
                 sp = std::sin(pitch[i]), cy = std::cos(yaw[i]), sy = std::sin(yaw[i]);
    Eigen::Matrix3d c;
    c << cp * cy, sr * sp * cy - cr * sy, cr * sp * cy + sr * sy,  //
        cp * sy, sr * sp * sy + cr * cy, cr * sp * sy - sr * cy,   //
        -sp, sr * cp, cr * cp;
    t.cnb.push_back(c);
  }
  return t;
}

FilterSettings filter_model(double dt_s, double lat1, const ModelSigmas& s) {
  FilterSettings f;
  f.taus = s.taus;
  f.r_nT2 = s.meas_var_nT2;
  Eigen::VectorXd p0(18);
  const double dlat =
      s.init_pos_m * std::sqrt(1 - std::pow(kEccentricity * std::sin(lat1), 2)) / kEarthRadius_m;
  p0 << dlat * dlat, std::pow(dlat / std::cos(lat1), 2), s.init_alt_m * s.init_alt_m,
      Eigen::Vector3d::Constant(s.init_vel_mps * s.init_vel_mps),
      Eigen::Vector3d::Constant(s.init_att_rad * s.init_att_rad), s.ha_m * s.ha_m,
      s.a_hat_mps2 * s.a_hat_mps2, Eigen::Vector3d::Constant(s.acc_mps2 * s.acc_mps2),
      Eigen::Vector3d::Constant(s.gyro_rps * s.gyro_rps), s.fogm_nT * s.fogm_nT;
  f.p0 = p0.asDiagonal();
  Eigen::VectorXd q(18);
  q << Eigen::Vector3d::Constant(1e-30), Eigen::Vector3d::Constant(s.vrw * s.vrw),
      Eigen::Vector3d::Constant(s.arw * s.arw), 2 * s.baro_m * s.baro_m / s.taus.baro_s, 1e-30,
      Eigen::Vector3d::Constant(2 * s.acc_mps2 * s.acc_mps2 / s.taus.acc_s),
      Eigen::Vector3d::Constant(2 * s.gyro_rps * s.gyro_rps / s.taus.gyro_s),
      2 * s.fogm_nT * s.fogm_nT / s.taus.fogm_s;
  f.qd = (q * dt_s).asDiagonal();
  return f;
}

PositionErrors position_errors(const NavTrack& track, const Eigen::MatrixXd& x,
                               const Eigen::VectorXd& true_lat, const Eigen::VectorXd& true_lon) {
  const Eigen::Index n = track.size();
  if (true_lat.size() != n || true_lon.size() != n)
    throw Error("position errors: the truth and the track differ in length");
  PositionErrors e;
  e.north_m.resize(n);
  e.east_m.resize(n);
  double ss = 0;
  for (Eigen::Index i = 0; i < n; ++i) {
    const double lat = track.lat_rad[i] + (x.size() ? x(0, i) : 0.0);
    const double lon = track.lon_rad[i] + (x.size() ? x(1, i) : 0.0);
    e.north_m[i] = dlat_to_north_m(lat - true_lat[i], true_lat[i]);
    e.east_m[i] = dlon_to_east_m(lon - true_lon[i], true_lat[i]);
    ss += e.north_m[i] * e.north_m[i] + e.east_m[i] * e.east_m[i];
  }
  e.drms_m = n ? std::sqrt(ss / static_cast<double>(n)) : 0.0;
  return e;
}

double covariance_drms_m(const std::vector<Eigen::MatrixXd>& p, const Eigen::VectorXd& lat) {
  double ss = 0;
  for (size_t i = 0; i < p.size(); ++i) {
    const double l = lat[static_cast<Eigen::Index>(i)];
    const double n = dlat_to_north_m(std::sqrt(p[i](0, 0)), l);
    const double e = dlon_to_east_m(std::sqrt(p[i](1, 1)), l);
    ss += n * n + e * e;
  }
  return p.empty() ? 0.0 : std::sqrt(ss / static_cast<double>(p.size()));
}

}  // namespace magcomp::nav
