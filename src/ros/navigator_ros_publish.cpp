// magcomp ROS layer: the navigator's outputs: the map for rviz, and each step's odometry, pose,
// fix, status, paths and transform (see navigator_ros.h).
#include "magcomp/ros/navigator_ros.h"

#include <geometry_msgs/PoseWithCovarianceStamped.h>
#include <magcomp/NavigationStatus.h>
#include <nav_msgs/OccupancyGrid.h>
#include <nav_msgs/Odometry.h>

#include <algorithm>
#include <cmath>
#include <set>

#include "held_samples.h"
#include "magcomp/core/error.h"
#include "magcomp/core/geo/attitude.h"
#include "magcomp/core/math/constants.h"
#include "magcomp/core/nav/nav_model.h"
#include "magcomp/core/nav/online_calibration.h"
#include "magcomp/ros/callback_guard.h"
#include "magcomp/ros/params.h"

namespace magcomp::rosio {

void NavigatorRos::publish_map() {
  // The anomaly map for rviz: an OccupancyGrid in the map frame (its cells 0-100 spanning the
  // map's range; the grid's lat/lon axes laid on east/north at its corner, to a few metres
  // over a survey block).
  nav_msgs::OccupancyGrid g;
  g.header.frame_id = map_frame_;
  g.header.stamp = ros::Time(0);
  const Eigen::Index ny = map_.map_nT.rows(), nx = map_.map_nT.cols();
  const Eigen::Vector2d step = map_.step_m();
  g.info.resolution = static_cast<float>(0.5 * (step.x() + step.y()));
  g.info.width = static_cast<uint32_t>(nx);
  g.info.height = static_cast<uint32_t>(ny);
  const Eigen::Vector3d corner =
      enu_->forward(map_.lat_rad[0] * kRadToDeg, map_.lon_rad[0] * kRadToDeg, map_.alt_m);
  g.info.origin.position.x = corner.x();
  g.info.origin.position.y = corner.y();
  g.info.origin.position.z = corner.z();
  g.info.origin.orientation.w = 1.0;
  const double lo = map_.map_nT.minCoeff(), hi = map_.map_nT.maxCoeff();
  g.data.resize(static_cast<size_t>(nx * ny));
  for (Eigen::Index r = 0; r < ny; ++r)
    for (Eigen::Index c = 0; c < nx; ++c) {
      const bool valid = map_.mask.size() == 0 || map_.mask(r, c) != 0;
      g.data[static_cast<size_t>(r * nx + c)] = static_cast<int8_t>(
          valid && hi > lo ? std::lround(100.0 * (map_.map_nT(r, c) - lo) / (hi - lo)) : -1);
    }
  pub_map_.publish(g);
}

void NavigatorRos::on_timer() {
  guarded("magcomp navigator", &callback_errors_, [&] {
    // A measurement source silent for max_wait_s (wall): the INS samples waiting go without one.
    if (nav_ && nav_->pending() > 0 &&
        ros::WallTime::now().toSec() - last_input_wall_s_ > max_wait_s_)
      publish(nav_->flush());
  });
}

namespace {

// A pose in the map frame: position pos_enu_m (m), attitude q (base_link to ENU), position
// covariance cov_enu_m2 (m^2). The attitude is the INS's: its uncertainty is not estimated here
// (a large value, so a fusion node takes it from the INS).
geometry_msgs::PoseWithCovariance pose_of(const Eigen::Vector3d& pos_enu_m,
                                          const Eigen::Quaterniond& q,
                                          const Eigen::Matrix3d& cov_enu_m2) {
  geometry_msgs::PoseWithCovariance pose;
  pose.pose.position.x = pos_enu_m.x();
  pose.pose.position.y = pos_enu_m.y();
  pose.pose.position.z = pos_enu_m.z();
  pose.pose.orientation.w = q.w();
  pose.pose.orientation.x = q.x();
  pose.pose.orientation.y = q.y();
  pose.pose.orientation.z = q.z();
  for (int i = 0; i < 3; ++i)
    for (int j = 0; j < 3; ++j) pose.covariance[static_cast<size_t>(6 * i + j)] = cov_enu_m2(i, j);
  for (int i = 3; i < 6; ++i) pose.covariance[static_cast<size_t>(7 * i)] = 1e3;
  return pose;
}

}  // namespace

void NavigatorRos::publish(const std::vector<nav::NavigatorOutput>& steps) {
  for (const nav::NavigatorOutput& o : steps) {
    const ros::Time stamp(o.t_s);
    const Eigen::Vector3d pos =
        enu_->forward(o.lat_rad * kRadToDeg, o.lon_rad * kRadToDeg, o.alt_m);
    const Eigen::Matrix3d cov = ned_to_enu_covariance(o.position_cov_ned_m2);
    Eigen::Quaterniond q = Eigen::Quaterniond::Identity();
    auto qi = orientations_.find(o.t_s);
    if (qi != orientations_.end()) q = qi->second;
    prune_before(orientations_, o.t_s);
    const geometry_msgs::PoseWithCovariance pose = pose_of(pos, q, cov);
    if (pub_odom_.getNumSubscribers() > 0)
      publish_odometry(stamp, pose, q, LocalEnu::ned_to_enu() * o.velocity_ned_mps);
    geometry_msgs::PoseWithCovarianceStamped ps;
    ps.header.stamp = stamp;
    ps.header.frame_id = map_frame_;
    ps.pose = pose;
    pub_pose_.publish(ps);
    publish_fix(o, stamp, cov);
    const double nis = publish_status(o, stamp);
    if (std::isfinite(nis) && o.step.updated) {
      nis_sum_ += nis;
      ++nis_n_;
    }
    consecutive_off_map_ = o.step.on_map ? 0 : consecutive_off_map_ + 1;
    if (tf_) {
      geometry_msgs::TransformStamped tf;
      tf.header.stamp = stamp;
      tf.header.frame_id = map_frame_;
      tf.child_frame_id = base_frame_;
      tf.transform.translation.x = pos.x();
      tf.transform.translation.y = pos.y();
      tf.transform.translation.z = pos.z();
      tf.transform.rotation = pose.pose.orientation;
      tf_->sendTransform(tf);
    }
    geometry_msgs::PoseStamped p;
    p.header = ps.header;
    p.pose = pose.pose;
    publish_paths(o, p);
    ++published_;
    last_ = o;
  }
}

void NavigatorRos::publish_odometry(const ros::Time& stamp,
                                    const geometry_msgs::PoseWithCovariance& pose,
                                    const Eigen::Quaterniond& q, const Eigen::Vector3d& vel_enu) {
  nav_msgs::Odometry odom;
  odom.header.stamp = stamp;
  odom.header.frame_id = map_frame_;
  odom.child_frame_id = base_frame_;
  odom.pose = pose;
  // The twist is in the child frame (base_link, x forward y left z up).
  const Eigen::Vector3d v_body = q.conjugate() * vel_enu;
  odom.twist.twist.linear.x = v_body.x();
  odom.twist.twist.linear.y = v_body.y();
  odom.twist.twist.linear.z = v_body.z();
  for (int i = 0; i < 6; ++i)
    odom.twist.covariance[static_cast<size_t>(7 * i)] = i < 3 ? 0.01 : 1e3;
  pub_odom_.publish(odom);
}

void NavigatorRos::publish_fix(const nav::NavigatorOutput& o, const ros::Time& stamp,
                               const Eigen::Matrix3d& cov) {
  sensor_msgs::NavSatFix fix;
  fix.header.stamp = stamp;
  fix.header.frame_id = base_frame_;
  fix.status.status = o.step.on_map ? sensor_msgs::NavSatStatus::STATUS_FIX
                                    : sensor_msgs::NavSatStatus::STATUS_NO_FIX;
  fix.latitude = o.lat_rad * kRadToDeg;
  fix.longitude = o.lon_rad * kRadToDeg;
  fix.altitude = o.alt_m;
  for (int i = 0; i < 3; ++i)
    for (int j = 0; j < 3; ++j) fix.position_covariance[static_cast<size_t>(3 * i + j)] = cov(i, j);
  fix.position_covariance_type = sensor_msgs::NavSatFix::COVARIANCE_TYPE_KNOWN;
  pub_fix_.publish(fix);
}

double NavigatorRos::publish_status(const nav::NavigatorOutput& o, const ros::Time& stamp) {
  magcomp::NavigationStatus st;
  st.header.stamp = stamp;
  st.header.frame_id = map_frame_;
  st.measurement_nT = o.measurement_nT;
  st.map_nT = o.map_nT;
  st.catch_all_nT = o.catch_all_nT;
  st.innovation_nT = o.step.innovation_nT;
  st.innovation_sigma_nT = std::sqrt(o.step.innovation_var_nT2);
  st.nis = o.step.innovation_nT * o.step.innovation_nT / o.step.innovation_var_nT2;
  st.measurement_sigma_nT = std::sqrt(o.measurement_var_nT2);
  st.measurement_used = o.step.updated;
  st.on_map = o.step.on_map;
  st.sigma_north_m = std::sqrt(o.position_cov_ned_m2(0, 0));
  st.sigma_east_m = std::sqrt(o.position_cov_ned_m2(1, 1));
  st.correction_north_m = nav::dlat_to_north_m(o.lat_rad - o.ins_lat_rad, o.lat_rad);
  st.correction_east_m = nav::dlon_to_east_m(o.lon_rad - o.ins_lon_rad, o.lat_rad);
  st.error_north_m = st.error_east_m = st.error_horizontal_m = st.ins_error_horizontal_m = NAN;
  auto tr = truth_.find(o.t_s);
  if (tr != truth_.end()) {
    const double tl = tr->second.x() * kDegToRad, tn = tr->second.y() * kDegToRad;
    st.error_north_m = nav::dlat_to_north_m(o.lat_rad - tl, tl);
    st.error_east_m = nav::dlon_to_east_m(o.lon_rad - tn, tl);
    st.error_horizontal_m = std::hypot(st.error_north_m, st.error_east_m);
    st.ins_error_horizontal_m = std::hypot(nav::dlat_to_north_m(o.ins_lat_rad - tl, tl),
                                           nav::dlon_to_east_m(o.ins_lon_rad - tn, tl));
  }
  prune_before(truth_, o.t_s);
  pub_status_.publish(st);
  if (online_ && o.coefficients.size() > 0) {  // what the filter has learned, plain numbers
    for (auto [pub, v] : {std::pair{&pub_coefficients_, &o.coefficients},
                          std::pair{&pub_coefficient_sigma_, &o.coefficient_sigma}}) {
      if (pub->getNumSubscribers() == 0) continue;
      magcomp::AuxChannels c;
      c.header.stamp = stamp;
      c.header.frame_id = map_frame_;
      c.names = column_names_;
      c.values.assign(v->data(), v->data() + v->size());
      pub->publish(c);
    }
  }
  return st.nis;
}

void NavigatorRos::publish_paths(const nav::NavigatorOutput& o,
                                 const geometry_msgs::PoseStamped& filter) {
  if (published_ % path_stride_ != 0) return;
  path_filter_.poses.push_back(filter);
  geometry_msgs::PoseStamped p = filter;
  const Eigen::Vector3d ins =
      enu_->forward(o.ins_lat_rad * kRadToDeg, o.ins_lon_rad * kRadToDeg, o.ins_alt_m);
  p.pose.position.x = ins.x();
  p.pose.position.y = ins.y();
  p.pose.position.z = ins.z();
  path_ins_.poses.push_back(p);
  if (path_filter_.poses.size() % 20 != 0) return;
  for (auto pair : {std::make_pair(&path_filter_, &pub_path_filter_),
                    std::make_pair(&path_ins_, &pub_path_ins_),
                    std::make_pair(&path_truth_, &pub_path_truth_)}) {
    pair.first->header.stamp = filter.header.stamp;
    pair.second->publish(*pair.first);
  }
}

}  // namespace magcomp::rosio
