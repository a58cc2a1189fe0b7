// magcomp: the map-matching navigator online (streaming_navigator.h).
#include "magcomp/core/nav/streaming_navigator.h"

#include <cmath>

#include "magcomp/core/math/constants.h"
#include "magcomp/core/nav/nav_model.h"

namespace magcomp::nav {
namespace {

constexpr double kMatchFraction = 0.25;       // a measurement belongs to an INS stamp within dt/4
constexpr double kGapSteps = 1.5;             // a step longer than this many dt is a gap
constexpr double kMaxPropagation_s = 3600.0;  // a longer gap restarts the filter
constexpr double kMaxLatitude_rad = (90.0 - 0.5) * kDegToRad;
constexpr double kMinAltitude_m = -12000.0, kMaxAltitude_m = 100000.0;
// Beyond any aircraft: an INS sample this fast from the last starts a new track (a jump).
constexpr double kMaxSpeed_mps = 2000.0;
// A correction or a 1-sigma position beyond this is no navigation: the filter restarts.
constexpr double kMaxCorrection_m = 1e6;

// A step's output that can be handed on: finite, its correction of the INS and its horizontal
// sigma within kMaxCorrection_m.
bool usable_output(const NavigatorOutput& o) {
  if (!(std::isfinite(o.lat_rad) && std::isfinite(o.lon_rad) && std::isfinite(o.alt_m) &&
        o.velocity_ned_mps.allFinite() && o.position_cov_ned_m2.allFinite() &&
        o.coefficients.allFinite() && o.coefficient_sigma.allFinite()))
    return false;
  const double north = dlat_to_north_m(o.lat_rad - o.ins_lat_rad, o.ins_lat_rad);
  const double east = dlon_to_east_m(o.lon_rad - o.ins_lon_rad, o.ins_lat_rad);
  const double var = o.position_cov_ned_m2(0, 0) + o.position_cov_ned_m2(1, 1);
  return std::hypot(north, east) <= kMaxCorrection_m && var <= kMaxCorrection_m * kMaxCorrection_m;
}

}  // namespace

Eigen::MatrixXd StreamingNavigator::coefficient_covariance() const {
  const Eigen::Index k = ekf_.p_post().rows() - 18;
  return ekf_.p_post().bottomRightCorner(k, k);
}

std::string invalid_ins_reason(const InsSample& s) {
  if (!std::isfinite(s.t_s)) return "stamp not finite";
  if (!std::isfinite(s.lat_rad) || !std::isfinite(s.lon_rad) || !std::isfinite(s.alt_m))
    return "position not finite";
  if (!std::isfinite(s.roll_rad) || !std::isfinite(s.pitch_rad) || !std::isfinite(s.yaw_rad))
    return "attitude not finite";
  if (std::abs(s.lat_rad) > kMaxLatitude_rad) return "latitude within 0.5 deg of a pole";
  if (std::abs(s.lon_rad) > 4 * kPi) return "longitude beyond 720 deg";
  if (s.alt_m < kMinAltitude_m || s.alt_m > kMaxAltitude_m) return "altitude outside [-12, 100] km";
  return "";
}

StreamingNavigator::StreamingNavigator(const AnomalyMap& map, const FilterSettings& settings,
                                       double dt_s, const ParticleSettings* cold_start)
    : map_(map), settings_(settings), dt_s_(dt_s), ekf_(map, settings), track_(dt_s) {
  if (cold_start) {
    pf_ = std::make_unique<ParticleFilter>(map, *cold_start);
    pf_active_ = true;
  }
}

void StreamingNavigator::reset() {
  ekf_.reset();
  if (pf_) {
    pf_->reset();
    pf_active_ = true;
    handover_t_s_ = first_step_t_s_ = NAN;
  }
  track_.flush();
  waiting_.clear();
  measurements_.clear();
  last_ins_t_ = last_meas_t_ = last_step_t_ = NAN;
}

std::vector<NavigatorOutput> StreamingNavigator::push_ins(const InsSample& s) {
  if (!invalid_ins_reason(s).empty()) {
    ++counts_.invalid_ins;
    return {};
  }
  if (std::isfinite(last_ins_t_) && !(s.t_s > last_ins_t_)) {
    ++counts_.out_of_order;
    return {};
  }
  ++counts_.ins_in;
  if (std::isfinite(last_ins_t_) && s.t_s - last_ins_t_ > kGapSteps * dt_s_) {
    ++counts_.gaps;  // the track's differences must not span the gap: end it there
    for (const TrackPoint& p : track_.flush()) waiting_.push_back(p);
  } else if (std::isfinite(last_ins_t_)) {
    const double north = dlat_to_north_m(s.lat_rad - last_ins_.lat_rad, s.lat_rad);
    const double east = dlon_to_east_m(s.lon_rad - last_ins_.lon_rad, s.lat_rad);
    if (std::hypot(north, east, s.alt_m - last_ins_.alt_m) >
        kMaxSpeed_mps * (s.t_s - last_ins_t_)) {
      ++counts_.ins_jumps;  // no aircraft moves so: the track starts again there
      for (const TrackPoint& p : track_.flush()) waiting_.push_back(p);
    }
  }
  last_ins_t_ = s.t_s;
  last_ins_ = s;
  for (const TrackPoint& p : track_.push(s)) waiting_.push_back(p);
  return drain(false);
}

std::vector<NavigatorOutput> StreamingNavigator::push_measurement(double t_s, double z_nT,
                                                                  double var_nT2,
                                                                  const Eigen::VectorXd* columns) {
  if (!std::isfinite(t_s)) {
    ++counts_.invalid_measurements;
    return {};
  }
  // Beyond any magnetic field: counted here, stepped without it (run_step).
  if (!(std::abs(z_nT) <= kMaxField_nT) && !std::isnan(z_nT)) ++counts_.invalid_measurements;
  if (std::isfinite(last_meas_t_) && !(t_s > last_meas_t_)) {
    ++counts_.out_of_order;
    return {};
  }
  ++counts_.measurements_in;
  last_meas_t_ = t_s;
  if (std::isfinite(last_step_t_) && t_s < last_step_t_ + kMatchFraction * dt_s_) {
    ++counts_.unmatched_measurements;  // its INS sample has been stepped without it
    return {};
  }
  measurements_[t_s] = {z_nT, var_nT2, columns ? *columns : Eigen::VectorXd()};
  return drain(false);
}

std::vector<NavigatorOutput> StreamingNavigator::end_of_ins() {
  for (const TrackPoint& p : track_.flush()) waiting_.push_back(p);
  last_ins_t_ = NAN;
  return drain(false);
}

std::vector<NavigatorOutput> StreamingNavigator::flush() { return drain(true); }

std::vector<NavigatorOutput> StreamingNavigator::drain(bool force) {
  std::vector<NavigatorOutput> out;
  const double tol = kMatchFraction * dt_s_;
  while (!waiting_.empty()) {
    const TrackPoint p = waiting_.front();
    // Measurements before this stamp belong to no INS sample.
    auto it = measurements_.begin();
    while (it != measurements_.end() && it->first < p.t_s - tol) {
      ++counts_.unmatched_measurements;
      it = measurements_.erase(it);
    }
    Measurement m;
    bool missing = false;
    if (it != measurements_.end() && it->first <= p.t_s + tol) {
      m = std::move(it->second);
      measurements_.erase(it);
    } else if (!(std::isfinite(last_meas_t_) && last_meas_t_ > p.t_s + tol) && !force) {
      break;  // its measurement may still come
    } else {
      ++counts_.missing_measurements;
      missing = true;
    }
    waiting_.pop_front();
    out.push_back(run_step(p, m, missing));
  }
  return out;
}

NavigatorOutput StreamingNavigator::run_step(const TrackPoint& p, const Measurement& m_in,
                                             bool missing) {
  Measurement m = m_in;
  double& z = m.z_nT;
  if (std::isfinite(last_step_t_) && p.t_s - last_step_t_ > kMaxPropagation_s) {
    ekf_.reset();  // an hour and more without the INS: start again from the prior
    ++counts_.filter_restarts;
  } else if (std::isfinite(last_step_t_) && p.t_s - last_step_t_ > kGapSteps * dt_s_) {
    ekf_.propagate(last_point_.point, p.t_s - last_step_t_ - dt_s_);  // across the gap
  }
  const bool refused = !std::isnan(z) && !(std::abs(z) <= kMaxField_nT);  // counted when pushed
  if (refused) z = NAN;
  if (std::isnan(first_step_t_s_)) first_step_t_s_ = p.t_s;
  NavigatorOutput o = pf_active_ ? particle_output(p, m) : step_output(p, m);
  if (!usable_output(o)) {  // never handed on: the filter restarts from its prior
    ekf_.reset();
    ++counts_.filter_restarts;
    o = pf_active_ ? particle_output(p, Measurement{}) : step_output(p, Measurement{});
  }
  ++counts_.steps;
  counts_.updates += o.step.updated;
  counts_.off_map += std::isfinite(z) && !o.step.on_map;
  counts_.gated += o.step.gated;
  counts_.nan_measurements += std::isnan(z) && !missing && !refused;
  last_step_t_ = p.t_s;
  last_point_ = p;
  return o;
}

NavigatorOutput StreamingNavigator::particle_output(const TrackPoint& p, const Measurement& m) {
  // With online calibration the particles see the measurement compensated by the prior.
  double z = m.z_nT;
  if (settings_.c0.size() > 0)
    z = m.columns.size() == settings_.c0.size() ? z - m.columns.dot(settings_.c0) : NAN;
  const double r = std::isfinite(m.var_nT2) && m.var_nT2 > 0 ? m.var_nT2 : settings_.r_nT2;
  pf_->step(p.lat_rad, p.lon_rad, z, r, std::isfinite(last_step_t_) ? p.t_s - last_step_t_ : 0.0);
  const ParticleEstimate e = pf_->estimate();
  const double npr = dlat_to_north_m(1.0, p.lat_rad), epr = dlon_to_east_m(1.0, p.lat_rad);
  NavigatorOutput o;
  o.t_s = p.t_s;
  o.ins_lat_rad = p.lat_rad;
  o.ins_lon_rad = p.lon_rad;
  o.ins_alt_m = p.alt_m;
  o.lat_rad = p.lat_rad + e.offset_m.x() / npr;
  o.lon_rad = p.lon_rad + e.offset_m.y() / epr;
  o.alt_m = p.alt_m;
  o.velocity_ned_mps = Eigen::Vector3d(p.point.vn_mps, p.point.ve_mps, p.point.vd_mps);
  o.position_cov_ned_m2 = Eigen::Matrix3d::Zero();
  o.position_cov_ned_m2.topLeftCorner<2, 2>() = e.covariance_m2;
  o.position_cov_ned_m2(2, 2) = ekf_.p_post()(2, 2);
  o.measurement_nT = m.z_nT;
  o.measurement_var_nT2 = r;
  o.map_nT = map_.value(o.lat_rad, o.lon_rad);
  o.catch_all_nT = 0.0;
  o.step.on_map = map_.covers(o.lat_rad, o.lon_rad);
  o.step.updated = std::isfinite(z);
  if (o.step.updated) {
    o.step.innovation_nT = z - o.map_nT - e.measurement_offset_nT;
    o.step.innovation_var_nT2 = e.measurement_offset_var_nT2 + r;
  }
  if (settings_.c0.size() > 0) {
    o.coefficients = settings_.c0;
    o.coefficient_sigma = settings_.pc0.diagonal().cwiseSqrt();
  }
  ++counts_.particle_steps;
  if (e.gathered) {  // hand over: the EKF starts where the cloud is
    Eigen::Matrix2d p_rad2;
    p_rad2 << e.covariance_m2(0, 0) / (npr * npr), e.covariance_m2(0, 1) / (npr * epr),
        e.covariance_m2(1, 0) / (npr * epr), e.covariance_m2(1, 1) / (epr * epr);
    ekf_.start_at(e.offset_m.x() / npr, e.offset_m.y() / epr, p_rad2, e.measurement_offset_nT);
    pf_active_ = false;
    handover_t_s_ = p.t_s;
  }
  return o;
}

NavigatorOutput StreamingNavigator::step_output(const TrackPoint& p, const Measurement& m) {
  const double z = m.z_nT, var = m.var_nT2;
  NavigatorOutput o;
  o.t_s = p.t_s;
  o.ins_lat_rad = p.lat_rad;
  o.ins_lon_rad = p.lon_rad;
  o.ins_alt_m = p.alt_m;
  o.measurement_nT = z;
  o.measurement_var_nT2 = std::isfinite(var) && var > 0 ? var : settings_.r_nT2;
  o.step = ekf_.step(p.point, p.lat_rad, p.lon_rad, z, var, dt_s_,
                     m.columns.size() ? &m.columns : nullptr);
  const Eigen::VectorXd& x = ekf_.x_post();
  const Eigen::MatrixXd& cov = ekf_.p_post();
  o.lat_rad = p.lat_rad + x[0];
  o.lon_rad = p.lon_rad + x[1];
  o.alt_m = p.alt_m + x[2];
  o.velocity_ned_mps =
      Eigen::Vector3d(p.point.vn_mps, p.point.ve_mps, p.point.vd_mps) + x.segment<3>(3);
  const Eigen::Vector3d j(dlat_to_north_m(1.0, o.lat_rad), dlon_to_east_m(1.0, o.lat_rad), -1.0);
  o.position_cov_ned_m2 = j.asDiagonal() * cov.topLeftCorner<3, 3>() * j.asDiagonal();
  o.map_nT = map_.value(o.lat_rad, o.lon_rad);
  o.catch_all_nT = x[17];
  const Eigen::Index k = x.size() - 18;
  if (k > 0) {
    o.coefficients = x.tail(k);
    o.coefficient_sigma = cov.diagonal().tail(k).cwiseMax(0.0).cwiseSqrt();
  }
  return o;
}

}  // namespace magcomp::nav
