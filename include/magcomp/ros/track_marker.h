// magcomp ROS layer: the rviz view of the compensated track (a line coloured by the live error,
// with a legend of the colour scale), in a local east-north-up frame from the first fix.
#pragma once

#include <geometry_msgs/TransformStamped.h>
#include <visualization_msgs/MarkerArray.h>

#include <array>
#include <cmath>
#include <string>
#include <vector>

namespace magcomp::rosio {

class TrackMarker {
 public:
  /// frame: the local frame (origin at the first fix, x east, y north, z up, m); every `stride`
  /// outputs one point is kept, at most max_points.
  TrackMarker(std::string frame, int stride, size_t max_points = 50000);

  /// Adds an output at (lat_deg, lon_deg, alt_m) with its value (the live error, or the anomaly
  /// without a reference), nT. Returns true when the caller should publish (every 20 points).
  bool add(double lat_deg, double lon_deg, double alt_m, double value_nT);
  /// The track as a line strip coloured by the value about its median (blue below, grey at,
  /// red above), and a legend: the median and the scale's ends, in text, nT.
  visualization_msgs::MarkerArray markers(const ros::Time& stamp) const;
  /// The aircraft's last position in the local frame, as a transform frame -> child (translation
  /// only).
  geometry_msgs::TransformStamped pose(const ros::Time& stamp, const std::string& child) const;
  void clear();
  bool empty() const { return points_.empty(); }

  /// The colour of a value on a scale of +-limit: blue (negative) - grey (0) - red (positive).
  static std::array<float, 3> colour(double value, double limit);

 private:
  std::string frame_;
  int stride_;
  size_t max_points_;
  long seen_ = 0;
  double origin_lat_ = NAN, origin_lon_ = NAN, origin_alt_ = NAN;
  std::array<double, 3> last_{0, 0, 0};
  std::vector<std::array<double, 4>> points_;  // east m, north m, up m, value nT
};

}  // namespace magcomp::rosio
