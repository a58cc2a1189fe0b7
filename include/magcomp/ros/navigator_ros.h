// magcomp ROS layer: the map-matching navigator (one class; the node and the nodelet construct
// it). A thin shell over the core's StreamingNavigator: messages in, its steps out as
// nav_msgs/Odometry and PoseWithCovarianceStamped in the `map` frame (REP 105), a NavSatFix,
// a plain-numeric magcomp/NavigationStatus, rviz paths and diagnostics. Parameters:
// config/navigator.yaml.
#pragma once

#include <diagnostic_updater/diagnostic_updater.h>
#include <geometry_msgs/PoseStamped.h>
#include <geometry_msgs/PoseWithCovariance.h>
#include <magcomp/AuxChannels.h>
#include <magcomp/CompensatedField.h>
#include <nav_msgs/Path.h>
#include <ros/ros.h>
#include <sensor_msgs/Imu.h>
#include <sensor_msgs/NavSatFix.h>
#include <std_msgs/Time.h>
#include <std_srvs/Trigger.h>
#include <tf2_ros/transform_broadcaster.h>

#include <Eigen/Geometry>
#include <map>
#include <memory>
#include <optional>
#include <string>

#include "magcomp/core/geo/local_enu.h"
#include "magcomp/core/model/model.h"
#include "magcomp/core/nav/anomaly_map.h"
#include "magcomp/core/nav/nav_model.h"
#include "magcomp/core/nav/online_calibration.h"
#include "magcomp/core/nav/streaming_navigator.h"
#include "magcomp/core/stream/stamp_pairer.h"

namespace magcomp::rosio {

class NavigatorRos {
 public:
  /// Reads and validates the private parameters, loads the map (throws magcomp::Error naming
  /// the parameter or the file).
  NavigatorRos(ros::NodeHandle nh, ros::NodeHandle pnh);

 private:
  void on_anomaly(const magcomp::CompensatedField::ConstPtr& m);
  void on_ins_fix(const sensor_msgs::NavSatFix::ConstPtr& m);
  void on_imu(const sensor_msgs::Imu::ConstPtr& m);
  void on_truth(const sensor_msgs::NavSatFix::ConstPtr& m);
  void on_end(const std_msgs::Time::ConstPtr& m);
  /// Online calibration: the compensator's model columns, by stamp.
  void on_columns(const magcomp::AuxChannels::ConstPtr& m);
  /// ~save_model: the learned model to learned_model_path (atomic).
  bool on_save_model(std_srvs::Trigger::Request& req, std_srvs::Trigger::Response& res);
  // The callbacks' bodies (run guarded).
  void take_anomaly(const magcomp::CompensatedField& m);
  void take_ins_fix(const sensor_msgs::NavSatFix& m);
  void take_imu(const sensor_msgs::Imu& m);
  void take_truth(const sensor_msgs::NavSatFix& m);
  // A measurement for the filter (columns: online calibration's, else empty).
  struct EarlyMeasurement {
    double z_nT = NAN, var_nT2 = NAN;
    Eigen::VectorXd columns;
  };
  void feed_measurement(double t_s, const EarlyMeasurement& m);
  /// A stamp ROS time cannot carry back out (seconds at 2^32 - 1): counted, true.
  bool refuse_stamp(const ros::Time& stamp);
  void on_timer();
  /// The anomaly map as a latched nav_msgs/OccupancyGrid (rviz's Map display).
  void publish_map();
  /// An INS fix (deg, deg, m) and attitude with the same stamp: one sample for the navigator.
  struct InsAttitude {
    Eigen::Vector3d rpy_rad;       ///< roll, pitch, yaw (rad, NED/FRD)
    Eigen::Quaterniond q_enu_flu;  ///< the Imu's orientation (ENU/FLU)
  };
  using InsPairs = StampPairer<Eigen::Vector3d, InsAttitude>;
  void take_ins(const InsPairs::Pair& pair);
  /// A stamp earlier than the last of its own stream (`last_s`) by more than jump_back_s: a new
  /// flight (a looped bag); everything restarts.
  bool jumped_back(double t_s, double* last_s);
  /// Each step's outputs: odometry, pose, fix, status, what the filter learned, tf, paths.
  void publish(const std::vector<nav::NavigatorOutput>& steps);
  /// The odometry of a step: `pose` in the map frame, velocity vel_enu_mps (ENU, m/s) turned
  /// into base_link by the attitude q (base_link to ENU).
  void publish_odometry(const ros::Time& stamp, const geometry_msgs::PoseWithCovariance& pose,
                        const Eigen::Quaterniond& q, const Eigen::Vector3d& vel_enu_mps);
  /// The fix of a step, its position covariance cov_enu_m2 (ENU, m^2).
  void publish_fix(const nav::NavigatorOutput& o, const ros::Time& stamp,
                   const Eigen::Matrix3d& cov_enu_m2);
  /// The status of a step (and, online, its coefficients and their sigmas); returns its NIS.
  double publish_status(const nav::NavigatorOutput& o, const ros::Time& stamp);
  /// The filter's and the INS's paths, every path_stride-th step, published every 20 poses.
  void publish_paths(const nav::NavigatorOutput& o, const geometry_msgs::PoseStamped& filter);
  void diagnose(diagnostic_updater::DiagnosticStatusWrapper& stat);

  ros::NodeHandle nh_, pnh_;
  // Parameters (SI units, validated at start-up).
  std::string map_path_, map_frame_, base_frame_;
  double dt_s_ = 0.1, max_wait_s_ = 2.0, jump_back_s_ = 1.0, map_sigma_nT_ = 0.0;
  bool use_compensator_variance_ = false, publish_tf_ = false;
  int path_stride_ = 10;
  // The core.
  nav::AnomalyMap map_;
  nav::ModelSigmas sigmas_;
  double nis_gate_ = INFINITY;
  bool map_offset_from_first_ = true;
  /// Made at the first INS sample: the filter's initial covariance is about its latitude.
  std::unique_ptr<nav::StreamingNavigator> nav_;
  std::unique_ptr<LocalEnu> enu_;
  // INS halves waiting for their other half, by stamp: the fix and the attitude.
  InsPairs ins_pairs_;
  std::map<double, Eigen::Quaterniond> orientations_;  // the Imu's (ENU/FLU)
  std::map<double, Eigen::Vector2d> truth_;
  std::map<double, EarlyMeasurement> early_;  // measurements before the first INS sample
  // Online calibration: the model, its prior, the halves (anomaly, columns) waiting by stamp.
  bool online_ = false;
  std::optional<nav::ParticleSettings> cold_start_;  // init_pos_sigma_m > 100 m
  std::unique_ptr<Model> model_, prior_;
  nav::CoefficientPriorSettings prior_settings_;
  std::vector<std::string> column_names_;
  struct AnomalyHalf {
    double z_nT = NAN, var_nT2 = NAN;  ///< the raw anomaly and its variance (NaN: the settings')
  };
  using OnlinePairs = StampPairer<AnomalyHalf, Eigen::VectorXd>;
  OnlinePairs online_pairs_;  // the anomaly and the model's columns
  /// Online: the anomaly and the model's columns of one stamp, one measurement for the filter.
  void take_online(const OnlinePairs::Pair& pair);
  long columns_mismatched_ = 0;
  std::string learned_model_path_;
  ros::Subscriber sub_columns_;
  ros::Publisher pub_coefficients_, pub_coefficient_sigma_;
  ros::ServiceServer srv_save_;
  double last_anomaly_t_ = NAN, last_fix_t_ = NAN, last_imu_t_ = NAN;
  double last_input_wall_s_ = 0.0;
  // Counters and the latest state, for diagnostics.
  long truth_seen_ = 0;  // reference fixes received (every path_stride-th is a path point)
  long published_ = 0, jumps_back_ = 0, nan_inputs_ = 0;
  long ins_no_fix_ = 0, ins_refused_ = 0, bad_stamps_ = 0, callback_errors_ = 0;
  std::optional<nav::NavigatorOutput> last_;
  double nis_sum_ = 0.0;
  long nis_n_ = 0, consecutive_off_map_ = 0;
  // Outputs.
  ros::Subscriber sub_anomaly_, sub_fix_, sub_imu_, sub_truth_, sub_end_;
  ros::Publisher pub_odom_, pub_pose_, pub_fix_, pub_status_, pub_path_filter_, pub_path_ins_,
      pub_path_truth_, pub_map_;
  nav_msgs::Path path_filter_, path_ins_, path_truth_;
  std::unique_ptr<tf2_ros::TransformBroadcaster> tf_;
  ros::WallTimer timer_, diag_timer_;
  diagnostic_updater::Updater updater_;
};

}  // namespace magcomp::rosio
