// magcomp ROS layer: the compensator (one class; the node and the nodelet construct it).
#pragma once

#include <diagnostic_updater/diagnostic_updater.h>
#include <diagnostic_updater/publisher.h>
#include <magcomp/AuxChannels.h>
#include <magcomp/CalibrationStatus.h>
#include <magcomp/ScalarMagnetometer.h>
#include <ros/ros.h>
#include <sensor_msgs/Imu.h>
#include <sensor_msgs/MagneticField.h>
#include <sensor_msgs/NavSatFix.h>
#include <std_msgs/Time.h>
#include <std_srvs/Trigger.h>
#include <tf2_ros/buffer.h>
#include <tf2_ros/transform_broadcaster.h>
#include <tf2_ros/transform_listener.h>

#include <Eigen/Core>
#include <deque>
#include <memory>
#include <string>

#include "magcomp/core/flight_conditions.h"
#include "magcomp/core/inflight_calibrator.h"
#include "magcomp/core/streaming_compensator.h"
#include "magcomp/ros/track_marker.h"

namespace magcomp::rosio {

/// Subscribes to a scalar magnetometer, a fluxgate, the auxiliary channels, the GNSS fix and
/// optionally a reference magnetometer; interpolates every input to each scalar stamp (nothing is
/// dropped for being between two stamps); applies the fitted model sample by sample with the
/// core's StreamingCompensator; publishes magcomp/CompensatedField. Stamps come from the data.
/// Survives NaN, gaps, duplicate and out-of-order stamps and jumps back in time (reset), and
/// reports them in diagnostics. Reloads its model on ~reload or when the file changes, without
/// losing a sample. With ~calibration_model it also calibrates in flight (InflightCalibrator): the
/// calibrator node is this class with calibration on and, optionally, no model to apply.
/// Parameters: see config/compensator.yaml and config/calibrator.yaml.
class CompensatorRos {
 public:
  CompensatorRos(ros::NodeHandle nh, ros::NodeHandle pnh);

 private:
  struct Timed3 {
    double t;
    Eigen::Vector3d v;
  };
  struct TimedValues {
    double t;
    std::vector<double> v;
  };
  struct Timed1 {
    double t;
    double v;
  };

  bool load_model(const std::string& why);
  void on_scalar(const magcomp::ScalarMagnetometer::ConstPtr& m);
  void on_vector(const sensor_msgs::MagneticField::ConstPtr& m);
  void on_aux(const magcomp::AuxChannels::ConstPtr& m);
  void on_fix(const sensor_msgs::NavSatFix::ConstPtr& m);
  void on_reference(const magcomp::ScalarMagnetometer::ConstPtr& m);
  void on_imu(const sensor_msgs::Imu::ConstPtr& m);
  /// The source says it has nothing more (the player's end topic): emit every pending sample.
  void on_end_of_stream(const std_msgs::Time::ConstPtr& m);
  /// Emits what is pending: inputs not yet covering a sample are held (counted as stale).
  void flush_all();
  /// After the end-of-stream message: once every pending sample is out (each waits up to
  /// max_wait_s of wall time for late inputs), emits the compensator's lookahead.
  void finish_end_of_stream();
  bool on_reload(std_srvs::Trigger::Request&, std_srvs::Trigger::Response& res);
  void on_watch(const ros::TimerEvent&);
  void process_ready(bool force);
  void feed(const StreamSample& s);
  /// Index of each named channel in the AuxChannels messages (-1 when absent).
  std::vector<int> channel_indices(const std::vector<std::string>& names) const;
  /// Values of the indexed channels at t (interpolated; the latest when t is past the buffer).
  std::vector<double> channels_at(double t, const std::vector<int>& index);
  void publish(const StreamOutput& o);
  /// IGRF total field (nT) at data time t from the interpolated fix; NaN without a fix.
  double igrf_at(double t);
  void reset_streams(const char* why);
  void diagnose(diagnostic_updater::DiagnosticStatusWrapper& stat);
  // In-flight calibration.
  void calibrate(const StreamSample& s);
  void publish_calibration_status();
  bool on_start_segment(std_srvs::Trigger::Request&, std_srvs::Trigger::Response& res);
  bool on_stop_segment(std_srvs::Trigger::Request&, std_srvs::Trigger::Response& res);
  bool on_fit(std_srvs::Trigger::Request&, std_srvs::Trigger::Response& res);
  bool on_save(std_srvs::Trigger::Request&, std_srvs::Trigger::Response& res);
  bool on_reset_calibration(std_srvs::Trigger::Request&, std_srvs::Trigger::Response& res);
  template <typename T>
  static bool interpolate(const std::deque<T>& buf, double t, T* out);
  /// Appends to an input buffer in stamp order: a stamp not after the last is dropped, one far
  /// back (jump_back_s) clears the buffer first; samples older than buffer_s are pruned.
  template <typename T>
  bool append(std::deque<T>& buf, T item, long* late);
  /// Seconds since the first stamp's whole second: exact to the nanosecond in a double.
  double rel(const ros::Time& stamp);
  /// The stamp of a relative time.
  ros::Time stamp(double t) const;

  ros::NodeHandle nh_, pnh_;
  // Parameters (SI units, validated at start-up).
  std::string model_path_, frame_id_;
  double max_gap_s_ = 1.0, max_wait_s_ = 0.5, jump_back_s_ = 1.0, buffer_s_ = 10.0;
  bool watch_model_ = true;
  int marker_stride_ = 10;
  // State.
  std::unique_ptr<StreamingCompensator> comp_;
  std::string model_error_;
  double model_mtime_ = 0.0;
  struct PendingScalar {
    double t, value_nT, arrived_wall_s;
  };
  std::deque<PendingScalar> pending_scalar_;  // awaiting vector/aux coverage
  std::deque<Timed3> vectors_;
  std::deque<TimedValues> aux_;  // every channel of the AuxChannels messages (aux_all_names_)
  std::deque<Timed3> fixes_;     // lat deg, lon deg, alt m
  std::deque<Timed1> references_;
  std::deque<StreamSample>
      history_;  // recent samples (channels rebuilt per model), re-fed on a swap
  std::vector<std::string> aux_all_names_;  // names in the AuxChannels messages
  std::vector<int> channel_index_;  // the model's channel k -> index in aux_all_names_ (-1: absent)
  int diurnal_index_ = -1;
  double last_scalar_t_ = -1e300, last_published_t_ = -1e300;
  int64_t base_sec_ = -1;
  // Counters for diagnostics.
  long n_in_ = 0, n_out_ = 0, n_nan_ = 0, n_dup_ = 0, n_out_of_order_ = 0, n_jumps_ = 0,
       n_gaps_ = 0, n_stale_ = 0, n_reloads_ = 0;
  // Inputs (vector, aux, fix, reference) whose stamp is not after their topic's last one: they
  // came too late to be used and are dropped.
  long n_late_inputs_ = 0;
  // Wall-time flushes (flush_after_s of silence) after which the stream went on: the outputs
  // around them were computed without their successors, so they differ from the offline ones.
  long n_premature_flushes_ = 0;
  long n_aux_mismatch_ = 0;  // AuxChannels with names and values of different lengths (dropped)
  double flushed_at_t_ = NAN;  // data time of the last wall-time flush, NaN: none pending
  bool ending_ = false;        // end-of-stream received, pending samples still going out
  double last_vector_t_ = NAN;
  // ROS plumbing.
  ros::Subscriber sub_scalar_, sub_vector_, sub_aux_, sub_fix_, sub_ref_, sub_end_;
  ros::Publisher pub_out_, pub_marker_;
  ros::ServiceServer srv_reload_;
  ros::WallTimer watch_timer_, diag_timer_;
  ros::WallTime last_scalar_wall_;
  double flush_after_s_ = 1.0;
  diagnostic_updater::Updater updater_;
  double min_freq_ = 5.0, max_freq_ = 50.0;
  std::unique_ptr<diagnostic_updater::FrequencyStatus> freq_;
  std::unique_ptr<TrackMarker> track_;
  bool publish_track_tf_ = false;
  std::unique_ptr<tf2_ros::TransformBroadcaster> tf_broadcaster_;
  std::unique_ptr<InflightCalibrator> calibrator_;
  std::unique_ptr<Model> calibration_template_, calibrated_;
  std::string calibration_out_;
  std::vector<int> calibration_index_;  // the template's channels in the aux messages
  int line_index_ = -1;
  bool manual_segment_ = false;
  bool auto_segments_ = false;
  ManeuverDetector detector_;
  std::deque<Timed1> maneuver_;  // detector output (1: maneuver under way) by stamp
  ros::Subscriber sub_imu_;
  // Fluxgate mounting: vectors are rotated from their frame into base_frame_ with tf2.
  std::string base_frame_;
  std::unique_ptr<tf2_ros::Buffer> tf_buffer_;
  std::unique_ptr<tf2_ros::TransformListener> tf_listener_;
  std::string vector_frame_;
  Eigen::Matrix3d vector_rotation_ = Eigen::Matrix3d::Identity();
  bool rotation_known_ = false;
  double last_tf_try_wall_ = -1e9;  // wall time of the last mount lookup, s
  long n_no_tf_ = 0;
  ros::Publisher pub_status_;
  ros::ServiceServer srv_start_, srv_stop_, srv_fit_, srv_save_, srv_reset_;
  ros::WallTimer status_timer_;
};

}  // namespace magcomp::rosio
