// magcomp ROS layer: the track marker.
#include "magcomp/ros/track_marker.h"

#include <algorithm>
#include <cstdio>

#include "magcomp/core/math/constants.h"

namespace magcomp::rosio {
namespace {
constexpr int kPublishEvery = 20;  // points
constexpr double kLineWidth_m = 120.0;
constexpr double kTextHeight_m = 300.0;
}  // namespace

TrackMarker::TrackMarker(std::string frame, int stride, size_t max_points)
    : frame_(std::move(frame)), stride_(std::max(stride, 1)), max_points_(max_points) {}

void TrackMarker::clear() {
  points_.clear();
  seen_ = 0;
}

bool TrackMarker::add(double lat, double lon, double alt, double value) {
  if (!std::isfinite(lat) || !std::isfinite(lon)) return false;
  if (!std::isfinite(origin_lat_)) {
    origin_lat_ = lat;
    origin_lon_ = lon;
    origin_alt_ = std::isfinite(alt) ? alt : 0.0;
  }
  last_ = {(lon - origin_lon_) * kDegToRad * kMeanEarthRadius_m * std::cos(origin_lat_ * kDegToRad),
           (lat - origin_lat_) * kDegToRad * kMeanEarthRadius_m,
           std::isfinite(alt) ? alt - origin_alt_ : 0.0};
  if (seen_++ % stride_ != 0 || points_.size() >= max_points_) return false;
  points_.push_back({last_[0], last_[1], 0.0, value});
  return points_.size() % kPublishEvery == 0;
}

std::array<float, 3> TrackMarker::colour(double value, double limit) {
  if (!std::isfinite(value) || !(limit > 0)) return {0.6f, 0.6f, 0.6f};
  const double u = std::clamp(value / limit, -1.0, 1.0);
  // grey at 0, to saturated red (+) or blue (-)
  const float g = static_cast<float>(0.6 * (1.0 - std::abs(u)));
  return u >= 0 ? std::array<float, 3>{static_cast<float>(0.6 + 0.4 * u), g, g}
                : std::array<float, 3>{g, g, static_cast<float>(0.6 - 0.4 * u)};
}

visualization_msgs::MarkerArray TrackMarker::markers(const ros::Time& stamp) const {
  visualization_msgs::MarkerArray out;
  if (points_.empty()) return out;
  // Colours show the value about its median (a constant offset, such as the bias a band-pass fit
  // cannot see, would paint the whole track one colour); the scale is the 95th percentile of the
  // deviation, so one spike does not wash the colours out.
  std::vector<double> finite;
  for (const auto& p : points_)
    if (std::isfinite(p[3])) finite.push_back(p[3]);
  double centre = 0.0;
  if (!finite.empty()) {
    auto mid = finite.begin() + static_cast<std::ptrdiff_t>(finite.size() / 2);
    std::nth_element(finite.begin(), mid, finite.end());
    centre = *mid;
  }
  std::vector<double> mags;
  for (double v : finite) mags.push_back(std::abs(v - centre));
  double limit = 1e-3;
  if (!mags.empty()) {
    auto k =
        mags.begin() + static_cast<std::ptrdiff_t>(0.95 * static_cast<double>(mags.size() - 1));
    std::nth_element(mags.begin(), k, mags.end());
    limit = std::max(*k, 1e-3);
  }
  visualization_msgs::Marker line;
  line.header.frame_id = frame_;
  line.header.stamp = stamp;
  line.ns = "magcomp_track";
  line.id = 0;
  line.type = visualization_msgs::Marker::LINE_STRIP;
  line.action = visualization_msgs::Marker::ADD;
  line.pose.orientation.w = 1.0;
  line.scale.x = kLineWidth_m;
  line.color.a = 1.0f;
  for (const auto& p : points_) {
    geometry_msgs::Point pt;
    pt.x = p[0];
    pt.y = p[1];
    line.points.push_back(pt);
    const auto c = colour(p[3] - centre, limit);
    std_msgs::ColorRGBA rgba;
    rgba.r = c[0];
    rgba.g = c[1];
    rgba.b = c[2];
    rgba.a = 1.0f;
    line.colors.push_back(rgba);
  }
  out.markers.push_back(line);
  // The legend, beside the start of the track: the colour of -limit, 0 and +limit.
  const double values[3] = {-limit, 0.0, limit};
  for (int k = 0; k < 3; ++k) {
    visualization_msgs::Marker t;
    t.header = line.header;
    t.ns = "magcomp_legend";
    t.id = k;
    t.type = visualization_msgs::Marker::TEXT_VIEW_FACING;
    t.action = visualization_msgs::Marker::ADD;
    t.pose.orientation.w = 1.0;
    t.pose.position.x = points_.front()[0] - 3000.0;
    t.pose.position.y = points_.front()[1] + 1.5 * kTextHeight_m * (1 - k);
    t.scale.z = kTextHeight_m;
    const auto c = colour(values[k], limit);
    t.color.r = c[0];
    t.color.g = c[1];
    t.color.b = c[2];
    t.color.a = 1.0f;
    char buf[96];
    std::snprintf(buf, sizeof(buf), "%+.2f nT%s", centre + values[k], k == 1 ? " (median)" : "");
    t.text = buf;
    out.markers.push_back(t);
  }
  return out;
}

geometry_msgs::TransformStamped TrackMarker::pose(const ros::Time& stamp,
                                                  const std::string& child) const {
  geometry_msgs::TransformStamped tf;
  tf.header.stamp = stamp;
  tf.header.frame_id = frame_;
  tf.child_frame_id = child;
  tf.transform.translation.x = last_[0];
  tf.transform.translation.y = last_[1];
  tf.transform.translation.z = last_[2];
  tf.transform.rotation.w = 1.0;
  return tf;
}

}  // namespace magcomp::rosio
