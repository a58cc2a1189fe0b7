// magcomp: an INS track built sample by sample from positions and attitudes: the linearisation
// points of the navigation filter (velocity and specific force by central differences), two
// samples behind the input. track_from_positions() is this class run over a whole flight, so a
// node fed the same samples gets the same numbers bit for bit.
#pragma once

#include <deque>
#include <vector>

#include "magcomp/core/nav/pinson.h"

namespace magcomp::nav {

/// One INS sample: data time (s), position (rad, rad, m above the ellipsoid) and attitude (roll,
/// pitch, yaw; rad; yaw clockwise from north, NED/FRD).
struct InsSample {
  double t_s = 0.0;
  double lat_rad = 0.0, lon_rad = 0.0, alt_m = 0.0;
  double roll_rad = 0.0, pitch_rad = 0.0, yaw_rad = 0.0;
};

/// A sample of the track: time (s), position (rad, rad, m) and the filter's linearisation point
/// (NED velocity m/s, specific force m/s^2, body-to-NED attitude).
struct TrackPoint {
  double t_s = 0.0;
  double lat_rad = 0.0, lon_rad = 0.0, alt_m = 0.0;
  NavPoint point;
};

/// Body-to-NED rotation Rz(yaw) Ry(pitch) Rx(roll), angles in rad.
Eigen::Matrix3d body_to_ned(double roll_rad, double pitch_rad, double yaw_rad);

class StreamingTrack {
 public:
  /// Steps of dt_s seconds (> 0) between samples.
  explicit StreamingTrack(double dt_s);
  /// Takes the next sample; returns the points that became complete (the sample two back).
  std::vector<TrackPoint> push(const InsSample& s);
  /// The end of the stream: the last points (one-sided differences); then a new stream starts.
  std::vector<TrackPoint> flush();
  /// Samples taken but not yet returned.
  size_t pending() const { return samples_.size() - next_; }
  double dt_s() const { return dt_s_; }

 private:
  // Velocity (NED) of sample k of the buffer, given whether it is the last one of the stream.
  Eigen::Vector3d velocity(size_t k, bool last) const;
  TrackPoint point(size_t k, bool last) const;
  void drop_used();

  double dt_s_;
  // The samples of the stream from index base_ on, and their north/east offsets (m) from the
  // stream's first sample.
  std::deque<InsSample> samples_;
  std::deque<Eigen::Vector3d> ned_;  // north m, east m, altitude m
  double lat0_ = 0.0, lon0_ = 0.0;
  size_t next_ = 0;  // index (in samples_) of the next point to return
  bool first_ = true;
};

}  // namespace magcomp::nav
