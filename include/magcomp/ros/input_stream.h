// magcomp ROS layer: the inputs of a compensation, from topics into the core's StreamAligner.
#pragma once

#include <magcomp/AuxChannels.h>
#include <magcomp/ScalarMagnetometer.h>
#include <ros/ros.h>
#include <sensor_msgs/MagneticField.h>
#include <sensor_msgs/NavSatFix.h>
#include <std_msgs/Time.h>
#include <tf2_ros/buffer.h>
#include <tf2_ros/transform_listener.h>

#include <Eigen/Core>
#include <functional>
#include <memory>
#include <set>
#include <string>

#include "magcomp/core/stream/stream_aligner.h"

namespace magcomp::rosio {

/// Subscribes to a scalar magnetometer, a fluxgate, the auxiliary channels, the fix, optionally
/// a reference magnetometer and the player's end-of-stream message, and feeds them to a
/// StreamAligner in data time (seconds since the first stamp's whole second, exact to the
/// nanosecond). Fluxgate vectors are rotated from their frame into `base_frame` with the static
/// tf2 mount (looked up once) and converted from tesla (REP 145) to nT.
class InputStream {
 public:
  struct Topics {
    std::string scalar, vector, aux, fix, reference, end_of_stream;
  };
  /// Callbacks: after every message that may let samples out (`changed`), after a scalar stamp
  /// jumped back (`jumped_back`: the caller resets what it holds), on the end message (`ended`).
  struct Callbacks {
    std::function<void()> changed;
    std::function<void()> jumped_back;
    std::function<void(double data_time_s)> ended;
  };

  InputStream(ros::NodeHandle nh, const Topics& topics, const AlignerSettings& settings,
              uint32_t queue_size, bool tcp_nodelay, std::string base_frame, Callbacks callbacks);

  StreamAligner& aligner() { return aligner_; }
  const StreamAligner& aligner() const { return aligner_; }
  /// Data time of a stamp (s), and back.
  double rel(const ros::Time& stamp);
  ros::Time stamp(double t_s) const;
  /// Wall time (s) of the last scalar message.
  double last_scalar_wall_s() const { return last_scalar_wall_s_; }
  /// The fluxgate's frame once its mount is known ("" before), and the vectors used unrotated
  /// because the mount was not known yet.
  const std::string& vector_frame() const { return vector_frame_; }
  long vectors_without_tf() const { return n_no_tf_; }
  /// Messages dropped because their callback threw (callback_guard.h): the node lives on.
  long callback_errors() const { return callback_errors_; }
  const std::string& scalar_topic() const { return topics_.scalar; }

 private:
  void on_scalar(const magcomp::ScalarMagnetometer::ConstPtr& m);
  void on_vector(const sensor_msgs::MagneticField::ConstPtr& m);
  void on_aux(const magcomp::AuxChannels::ConstPtr& m);
  void on_fix(const sensor_msgs::NavSatFix::ConstPtr& m);
  void on_reference(const magcomp::ScalarMagnetometer::ConstPtr& m);
  void on_end(const std_msgs::Time::ConstPtr& m);

  Topics topics_;
  StreamAligner aligner_;
  Callbacks cb_;
  int64_t base_sec_ = -1;
  double last_scalar_wall_s_ = 0.0;
  std::string base_frame_, vector_frame_;
  Eigen::Matrix3d vector_rotation_ = Eigen::Matrix3d::Identity();
  bool rotation_known_ = false;
  double last_tf_try_wall_s_ = -1e9;
  long callback_errors_ = 0;
  long n_no_tf_ = 0;
  std::unique_ptr<tf2_ros::Buffer> tf_buffer_;
  std::unique_ptr<tf2_ros::TransformListener> tf_listener_;
  ros::Subscriber sub_scalar_, sub_vector_, sub_aux_, sub_fix_, sub_ref_, sub_end_;
};

/// The private parameters every node with an InputStream reads the same way: the aligner's
/// settings (s), the subscriptions' queue and TCP_NODELAY, the body frame, the topics (defaults:
/// magcomp/scalar/<scalar>, magcomp/fluxgate/<vector>, magcomp/aux, magcomp/ins/fix, no
/// reference, magcomp/end_of_stream). A bad value fails start-up naming its key (reject_param).
struct InputParams {
  AlignerSettings aligner;
  int queue_size = 1000;
  bool tcp_nodelay = true;
  std::string base_frame = "base_link";
  InputStream::Topics topics;
};
InputParams read_input_params(const ros::NodeHandle& pnh, const std::string& scalar,
                              const std::string& vector);

/// The names read_input_params reads, with a node's own (for warn_unknown_params).
std::set<std::string> with_input_params(std::set<std::string> own);

}  // namespace magcomp::rosio
