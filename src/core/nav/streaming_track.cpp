// magcomp: the navigation filter's linearisation points, sample by sample (streaming_track.h).
#include "magcomp/core/nav/streaming_track.h"

#include <cmath>

#include "magcomp/core/error.h"
#include "magcomp/core/math/constants.h"
#include "magcomp/core/nav/nav_model.h"

namespace magcomp::nav {

Eigen::Matrix3d body_to_ned(double roll, double pitch, double yaw) {
  const double cr = std::cos(roll), sr = std::sin(roll), cp = std::cos(pitch), sp = std::sin(pitch),
               cy = std::cos(yaw), sy = std::sin(yaw);
  Eigen::Matrix3d c;
  c << cp * cy, sr * sp * cy - cr * sy, cr * sp * cy + sr * sy,  //
      cp * sy, sr * sp * sy + cr * cy, cr * sp * sy - sr * cy,   //
      -sp, sr * cp, cr * cp;
  return c;
}

StreamingTrack::StreamingTrack(double dt_s) : dt_s_(dt_s) {
  if (!(dt_s > 0) || !std::isfinite(dt_s))
    throw Error("navigation track: the time step must be > 0 s");
}

// Rates as central differences per step (one-sided at the stream's ends), divided by dt: the
// velocity of sample k from the positions of k - 1 and k + 1.
Eigen::Vector3d StreamingTrack::velocity(size_t k, bool last) const {
  const size_t n = ned_.size();
  if (n < 2) return Eigen::Vector3d::Zero();
  Eigen::Vector3d d;
  if (k == 0 && first_) {
    d = (ned_[1] - ned_[0]) / dt_s_;
  } else if (last && k + 1 == n) {
    d = (ned_[k] - ned_[k - 1]) / dt_s_;
  } else {
    d = (ned_[k + 1] - ned_[k - 1]) / (2 * dt_s_);
  }
  d.z() = -d.z();  // altitude rate -> down velocity
  return d;
}

TrackPoint StreamingTrack::point(size_t k, bool last) const {
  const InsSample& s = samples_[k];
  TrackPoint p;
  p.t_s = s.t_s;
  p.lat_rad = s.lat_rad;
  p.lon_rad = s.lon_rad;
  p.alt_m = s.alt_m;
  const Eigen::Vector3d v = velocity(k, last);
  p.point.lat_rad = s.lat_rad;
  p.point.vn_mps = v.x();
  p.point.ve_mps = v.y();
  p.point.vd_mps = v.z();
  const size_t n = ned_.size();
  Eigen::Vector3d f = Eigen::Vector3d::Zero();
  if (n >= 2) {
    if (k == 0 && first_) {
      f = (velocity(1, last && n == 2) - v) / dt_s_;
    } else if (last && k + 1 == n) {
      f = (v - velocity(k - 1, false)) / dt_s_;
    } else {
      f = (velocity(k + 1, last && k + 2 == n) - velocity(k - 1, false)) / (2 * dt_s_);
    }
  }
  p.point.fn_mps2 = f.x();
  p.point.fe_mps2 = f.y();
  p.point.fd_mps2 = f.z() - kStandardGravity_mps2;
  p.point.cnb = body_to_ned(s.roll_rad, s.pitch_rad, s.yaw_rad);
  return p;
}

std::vector<TrackPoint> StreamingTrack::push(const InsSample& s) {
  if (samples_.empty() && first_) {
    lat0_ = s.lat_rad;
    lon0_ = s.lon_rad;
  }
  samples_.push_back(s);
  ned_.emplace_back(dlat_to_north_m(s.lat_rad - lat0_, s.lat_rad),
                    dlon_to_east_m(s.lon_rad - lon0_, s.lat_rad), s.alt_m);
  std::vector<TrackPoint> out;
  // Sample k needs the velocities of k - 1 and k + 1, so the positions up to k + 2.
  while (next_ + 2 < samples_.size()) {
    out.push_back(point(next_, false));
    ++next_;
    drop_used();
  }
  return out;
}

std::vector<TrackPoint> StreamingTrack::flush() {
  std::vector<TrackPoint> out;
  for (; next_ < samples_.size(); ++next_) out.push_back(point(next_, true));
  samples_.clear();
  ned_.clear();
  next_ = 0;
  first_ = true;
  return out;
}

void StreamingTrack::drop_used() {
  // Point k reads samples k - 2 .. k + 2: keep two before the next one.
  while (next_ > 2) {
    samples_.pop_front();
    ned_.pop_front();
    --next_;
    first_ = false;
  }
}

}  // namespace magcomp::nav
