// magcomp: INS tracks from positions, the filter's noise model, position errors in metres.
#include "magcomp/core/nav/nav_model.h"

#include <cmath>
#include <cstdio>

#include "magcomp/core/error.h"
#include "magcomp/core/geo/wgs84.h"
#include "magcomp/core/math/constants.h"
#include "magcomp/core/nav/streaming_track.h"

namespace magcomp::nav {

double dlat_to_north_m(double dlat, double lat) {
  return dlat / std::sqrt(1 - std::pow(kWgs84Eccentricity * std::sin(lat), 2)) * kWgs84SemiMajor_m;
}

double dlon_to_east_m(double dlon, double lat) {
  return dlon / std::sqrt(1 - std::pow(kWgs84Eccentricity * std::sin(lat), 2)) * kWgs84SemiMajor_m *
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
  for (Eigen::VectorXd* v : {&t.vn_mps, &t.ve_mps, &t.vd_mps, &t.fn_mps2, &t.fe_mps2, &t.fd_mps2})
    v->resize(n);
  t.cnb.reserve(static_cast<size_t>(n));
  // The streaming track, run over the whole flight: a node fed these samples gets these points.
  StreamingTrack stream(dt_s);
  Eigen::Index i = 0;
  const auto take = [&](const std::vector<TrackPoint>& points) {
    for (const TrackPoint& p : points) {
      t.vn_mps[i] = p.point.vn_mps;
      t.ve_mps[i] = p.point.ve_mps;
      t.vd_mps[i] = p.point.vd_mps;
      t.fn_mps2[i] = p.point.fn_mps2;
      t.fe_mps2[i] = p.point.fe_mps2;
      t.fd_mps2[i] = p.point.fd_mps2;
      t.cnb.push_back(p.point.cnb);
      ++i;
    }
  };
  for (Eigen::Index k = 0; k < n; ++k) {
    InsSample s;
    s.t_s = static_cast<double>(k) * dt_s;
    s.lat_rad = lat[k];
    s.lon_rad = lon[k];
    s.alt_m = alt[k];
    s.roll_rad = roll[k];
    s.pitch_rad = pitch[k];
    s.yaw_rad = yaw[k];
    take(stream.push(s));
  }
  take(stream.flush());
  return t;
}

void require_setting(double value, double lo, double hi, const std::string& name,
                     const std::string& unit, bool lo_closed) {
  const bool above = lo_closed ? value >= lo : value > lo;
  if (above && value <= hi) return;
  char buf[160];
  std::snprintf(buf, sizeof buf, ": must be in %s%g, %g] %s (got %g)", lo_closed ? "[" : "(", lo,
                hi, unit.c_str(), value);
  throw Error(name + buf);
}

FilterSettings filter_model(double dt_s, double lat1, const ModelSigmas& s) {
  FilterSettings f;
  f.taus = s.taus;
  f.r_nT2 = s.meas_var_nT2;
  f.map_representation_var = s.map_representation_var;
  Eigen::VectorXd p0(18);
  const double dlat = s.init_pos_m *
                      std::sqrt(1 - std::pow(kWgs84Eccentricity * std::sin(lat1), 2)) /
                      kWgs84SemiMajor_m;
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
  f.qd_step_s = dt_s;
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
