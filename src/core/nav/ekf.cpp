// magcomp: the map-matching error-state EKF and the Cramér-Rao bound (see ekf.h).
#include "magcomp/core/nav/ekf.h"

#include <cmath>

#include "magcomp/core/error.h"

namespace magcomp::nav {
namespace {

constexpr int kStates = 18;

// The measurement row: the map's gradient at the corrected position (lat, lon; the 2-D map has
// no vertical one) and 1 for the catch-all.
Eigen::RowVectorXd measurement_row(const AnomalyMap& map, double lat, double lon) {
  Eigen::RowVectorXd h = Eigen::RowVectorXd::Zero(kStates);
  const Eigen::Vector2d g = map.gradient(lat, lon);
  h[0] = g[0];
  h[1] = g[1];
  h[kStates - 1] = 1.0;
  return h;
}

// The measurement update of the covariance (and the gain it used): P = (I - K H) P.
Eigen::VectorXd update_covariance(const Eigen::RowVectorXd& h, double var, Eigen::MatrixXd* p) {
  const Eigen::VectorXd k = *p * h.transpose() / var;
  *p = (Eigen::MatrixXd::Identity(kStates, kStates) - k * h) * *p;
  return k;
}

void check(const NavTrack& track, const FilterSettings& s, const char* who) {
  const Eigen::Index n = track.size();
  for (const Eigen::VectorXd* v : {&track.lon_rad, &track.alt_m, &track.vn_mps, &track.ve_mps,
                                   &track.vd_mps, &track.fn_mps2, &track.fe_mps2, &track.fd_mps2})
    if (v->size() != n) throw Error(std::string(who) + ": the track's series differ in length");
  if (static_cast<Eigen::Index>(track.cnb.size()) != n)
    throw Error(std::string(who) + ": the track has " + std::to_string(track.cnb.size()) +
                " attitudes for " + std::to_string(n) + " samples");
  if (s.p0.rows() != kStates || s.p0.cols() != kStates || s.qd.rows() != kStates ||
      s.qd.cols() != kStates)
    throw Error(std::string(who) + ": P0 and Qd must be 18 x 18");
  if (!(s.r_nT2 > 0)) throw Error(std::string(who) + ": R must be > 0 nT^2");
}

}  // namespace

NavPoint NavTrack::point(Eigen::Index t) const {
  NavPoint p;
  p.lat_rad = lat_rad[t];
  p.vn_mps = vn_mps[t];
  p.ve_mps = ve_mps[t];
  p.vd_mps = vd_mps[t];
  p.fn_mps2 = fn_mps2[t];
  p.fe_mps2 = fe_mps2[t];
  p.fd_mps2 = fd_mps2[t];
  p.cnb = cnb[static_cast<size_t>(t)];
  return p;
}

FilterResult run_ekf(const NavTrack& ins, const Eigen::VectorXd& anomaly_nT, const AnomalyMap& map,
                     const FilterSettings& s) {
  check(ins, s, "ekf");
  const Eigen::Index n = ins.size();
  if (anomaly_nT.size() != n) throw Error("ekf: one measurement per INS sample is needed");
  FilterResult out;
  out.x.resize(kStates, n);
  out.p.reserve(static_cast<size_t>(n));
  out.innovation_nT.resize(n);
  out.innovation_var_nT2.resize(n);
  Eigen::VectorXd x = Eigen::VectorXd::Zero(kStates);
  Eigen::MatrixXd p = s.p0;
  for (Eigen::Index t = 0; t < n; ++t) {
    const Eigen::MatrixXd phi = pinson_transition(ins.point(t), s.taus, true, ins.dt_s);
    const double lat = ins.lat_rad[t] + x[0], lon = ins.lon_rad[t] + x[1];
    const double resid = anomaly_nT[t] - (map.value(lat, lon) + x[kStates - 1]);
    const Eigen::RowVectorXd h = measurement_row(map, lat, lon);
    const double var = (h * p * h.transpose())(0, 0) + s.r_nT2;
    if (std::isfinite(resid)) x += update_covariance(h, var, &p) * resid;  // NaN: predict only
    out.x.col(t) = x;
    out.p.push_back(p);
    out.innovation_nT[t] = resid;
    out.innovation_var_nT2[t] = var;
    x = phi * x;
    p = phi * p * phi.transpose() + s.qd;
  }
  return out;
}

std::vector<Eigen::MatrixXd> crlb(const NavTrack& truth, const AnomalyMap& map,
                                  const FilterSettings& s) {
  check(truth, s, "crlb");
  std::vector<Eigen::MatrixXd> out;
  out.reserve(static_cast<size_t>(truth.size()));
  Eigen::MatrixXd p = s.p0;
  for (Eigen::Index t = 0; t < truth.size(); ++t) {
    const Eigen::MatrixXd phi = pinson_transition(truth.point(t), s.taus, true, truth.dt_s);
    const Eigen::RowVectorXd h = measurement_row(map, truth.lat_rad[t], truth.lon_rad[t]);
    const double var = (h * p * h.transpose())(0, 0) + s.r_nT2;
    update_covariance(h, var, &p);
    out.push_back(p);
    p = phi * p * phi.transpose() + s.qd;
  }
  return out;
}

}  // namespace magcomp::nav
