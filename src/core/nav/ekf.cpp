// magcomp: the map-matching error-state EKF and the Cramér-Rao bound (see ekf.h).
#include "magcomp/core/nav/ekf.h"

#include <cmath>

#include "magcomp/core/error.h"

namespace magcomp::nav {
namespace {

constexpr int kStates = 18;

// The measurement row: the map's gradient at the corrected position (lat, lon; the 2-D map has
// no vertical one), 1 for the catch-all, and the model's columns for the coefficient states.
Eigen::RowVectorXd measurement_row(const AnomalyMap& map, double lat, double lon,
                                   const Eigen::VectorXd* columns = nullptr) {
  const Eigen::Index k = columns ? columns->size() : 0;
  Eigen::RowVectorXd h = Eigen::RowVectorXd::Zero(kStates + k);
  const Eigen::Vector2d g = map.gradient(lat, lon);
  h[0] = g[0];
  h[1] = g[1];
  h[kStates - 1] = 1.0;
  if (k > 0) h.tail(k) = columns->transpose();
  return h;
}

// The measurement update of the covariance (and the gain it used): P = (I - K H) P.
Eigen::VectorXd update_covariance(const Eigen::RowVectorXd& h, double var, Eigen::MatrixXd* p) {
  const Eigen::VectorXd k = *p * h.transpose() / var;
  *p = (Eigen::MatrixXd::Identity(h.size(), h.size()) - k * h) * *p;
  return k;
}

void check_settings(const FilterSettings& s, const char* who) {
  if (s.p0.rows() != kStates || s.p0.cols() != kStates || s.qd.rows() != kStates ||
      s.qd.cols() != kStates)
    throw Error(std::string(who) + ": P0 and Qd must be 18 x 18");
  const Eigen::Index k = s.c0.size();
  if (s.pc0.rows() != k || s.pc0.cols() != k || s.qc_per_s.size() != k)
    throw Error(std::string(who) + ": the coefficient states' prior and walk must match them");
  if (!s.c0.allFinite() || !s.pc0.allFinite() || !s.qc_per_s.allFinite())
    throw Error(std::string(who) + ": the coefficient states' prior is not finite");
  if (!(s.r_nT2 > 0) || !std::isfinite(s.r_nT2))
    throw Error(std::string(who) + ": R must be > 0 nT^2 and finite");
  if (!s.p0.allFinite() || !s.qd.allFinite())
    throw Error(std::string(who) +
                ": P0 or Qd is not finite (an initial or process sigma too large to square)");
}

void check(const NavTrack& track, const FilterSettings& s, const char* who) {
  check_settings(s, who);
  const Eigen::Index n = track.size();
  for (const Eigen::VectorXd* v : {&track.lon_rad, &track.alt_m, &track.vn_mps, &track.ve_mps,
                                   &track.vd_mps, &track.fn_mps2, &track.fe_mps2, &track.fd_mps2})
    if (v->size() != n) throw Error(std::string(who) + ": the track's series differ in length");
  if (static_cast<Eigen::Index>(track.cnb.size()) != n)
    throw Error(std::string(who) + ": the track has " + std::to_string(track.cnb.size()) +
                " attitudes for " + std::to_string(n) + " samples");
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

MapMatchingEkf::MapMatchingEkf(const AnomalyMap& map, const FilterSettings& settings)
    : map_(map), s_(settings) {
  check_settings(s_, "ekf");
  reset();
}

void MapMatchingEkf::reset() {
  const Eigen::Index k = s_.c0.size();
  x_ = Eigen::VectorXd::Zero(kStates + k);
  if (k == 0) {
    p_ = s_.p0;
  } else {  // the navigation block and the coefficients' prior, uncorrelated
    p_ = Eigen::MatrixXd::Zero(kStates + k, kStates + k);
    p_.topLeftCorner(kStates, kStates) = s_.p0;
    p_.bottomRightCorner(k, k) = s_.pc0;
    x_.tail(k) = s_.c0;
  }
  x_post_ = x_;
  p_post_ = p_;
  offset_nT_ = NAN;
}

void MapMatchingEkf::start_at(double dlat, double dlon, const Eigen::Matrix2d& p_rad2,
                              double offset_nT) {
  reset();
  x_[0] = dlat;
  x_[1] = dlon;
  p_.block(0, 0, 2, 2) = p_rad2;
  x_post_ = x_;
  p_post_ = p_;
  offset_nT_ = offset_nT;
}

MapMatchingEkf::Step MapMatchingEkf::step(const NavPoint& point, double lat_ins, double lon_ins,
                                          double anomaly_nT, double r_nT2, double dt_s,
                                          const Eigen::VectorXd* columns) {
  Step out;
  const Eigen::Index k = s_.c0.size();
  const double lat = lat_ins + x_[0], lon = lon_ins + x_[1];
  out.on_map = map_.covers(lat, lon);
  double r = std::isfinite(r_nT2) && r_nT2 > 0 ? r_nT2 : s_.r_nT2;
  if (s_.map_representation_var && out.on_map)
    r += map_.representation_var_nT2(lat, lon, p_.topLeftCorner<2, 2>());
  // Online calibration: the aircraft's field a.c the model predicts is part of the measurement.
  double aircraft_nT = 0.0;
  if (k > 0) {
    if (columns && columns->size() == k && columns->allFinite()) {
      aircraft_nT = columns->dot(x_.tail(k));
    } else {
      anomaly_nT = NAN;  // no columns: the measurement cannot be predicted
    }
  }
  if (s_.offset_from_first && std::isnan(offset_nT_) && std::isfinite(anomaly_nT) && out.on_map)
    offset_nT_ = anomaly_nT - aircraft_nT - map_.value(lat, lon);
  const double resid =
      anomaly_nT - offset_nT() - (map_.value(lat, lon) + x_[kStates - 1] + aircraft_nT);
  const Eigen::RowVectorXd h = k > 0 && std::isfinite(anomaly_nT)
                                   ? measurement_row(map_, lat, lon, columns)
                               : k > 0 ? Eigen::RowVectorXd(Eigen::RowVectorXd::Zero(kStates + k))
                                       : measurement_row(map_, lat, lon);
  const double var = (h * p_ * h.transpose())(0, 0) + r;
  out.innovation_nT = resid;
  out.innovation_var_nT2 = var;
  out.gated = std::isfinite(resid) && resid * resid / var > s_.nis_gate;
  if (std::isfinite(resid) && out.on_map && !out.gated) {  // else predict only
    x_ += update_covariance(h, var, &p_) * resid;
    out.updated = true;
  }
  x_post_ = x_;
  p_post_ = p_;
  propagate_by(point, dt_s, 1.0);
  return out;
}

// Propagation over dt_s, the navigation states' process noise qd scaled by `q_scale`: the
// transition acts on the 18 navigation states; the coefficients walk.
void MapMatchingEkf::propagate_by(const NavPoint& point, double dt_s, double q_scale) {
  const Eigen::MatrixXd phi = pinson_transition(point, s_.taus, true, dt_s);
  const Eigen::Index k = s_.c0.size();
  if (k == 0) {
    x_ = phi * x_;
    p_ = phi * p_ * phi.transpose() + (q_scale == 1.0 ? s_.qd : Eigen::MatrixXd(s_.qd * q_scale));
    return;
  }
  x_.head(kStates) = phi * x_.head(kStates);
  const Eigen::MatrixXd nav = p_.topLeftCorner(kStates, kStates);
  p_.topLeftCorner(kStates, kStates) = phi * nav * phi.transpose() + s_.qd * q_scale;
  p_.topRightCorner(kStates, k) = phi * p_.topRightCorner(kStates, k);
  p_.bottomLeftCorner(k, kStates) = p_.topRightCorner(kStates, k).transpose();
  p_.bottomRightCorner(k, k).diagonal() += s_.qc_per_s * dt_s;
}

void MapMatchingEkf::propagate(const NavPoint& point, double dt_s) {
  propagate_by(point, dt_s, std::isfinite(s_.qd_step_s) ? dt_s / s_.qd_step_s : 1.0);
}

FilterResult run_ekf(const NavTrack& ins, const Eigen::VectorXd& anomaly_nT, const AnomalyMap& map,
                     const FilterSettings& s, const Eigen::VectorXd* r_nT2) {
  check(ins, s, "ekf");
  const Eigen::Index n = ins.size();
  if (anomaly_nT.size() != n) throw Error("ekf: one measurement per INS sample is needed");
  if (r_nT2 && r_nT2->size() != n)
    throw Error("ekf: one measurement variance per sample is needed");
  FilterResult out;
  out.x.resize(s.states(), n);
  out.p.reserve(static_cast<size_t>(n));
  out.innovation_nT.resize(n);
  out.innovation_var_nT2.resize(n);
  MapMatchingEkf filter(map, s);
  for (Eigen::Index t = 0; t < n; ++t) {
    const MapMatchingEkf::Step st = filter.step(ins.point(t), ins.lat_rad[t], ins.lon_rad[t],
                                                anomaly_nT[t], r_nT2 ? (*r_nT2)[t] : NAN, ins.dt_s);
    out.x.col(t) = filter.x_post();
    out.p.push_back(filter.p_post());
    out.innovation_nT[t] = st.updated ? st.innovation_nT : NAN;
    out.innovation_var_nT2[t] = st.innovation_var_nT2;
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
    const double r = s.r_nT2 + (s.map_representation_var
                                    ? map.representation_var_nT2(truth.lat_rad[t], truth.lon_rad[t],
                                                                 Eigen::Matrix2d::Zero())
                                    : 0.0);
    const double var = (h * p * h.transpose())(0, 0) + r;
    update_covariance(h, var, &p);
    out.push_back(p);
    p = phi * p * phi.transpose() + s.qd;
  }
  return out;
}

}  // namespace magcomp::nav
