// magcomp ROS layer: the in-flight calibrator (one class; the node and the nodelet construct it).
#pragma once

#include <diagnostic_updater/diagnostic_updater.h>
#include <ros/ros.h>
#include <sensor_msgs/Imu.h>
#include <std_srvs/Trigger.h>

#include <deque>
#include <memory>
#include <string>

#include "magcomp/core/evaluate/flight_conditions.h"
#include "magcomp/core/fit/inflight_calibrator.h"
#include "magcomp/ros/input_stream.h"

namespace magcomp::rosio {

/// Parameters -> inputs aligned to each scalar stamp (InputStream) -> the core's
/// InflightCalibrator: recursive least squares while the calibration segments come in, a batch fit
/// (equal to `magcomp calibrate`) on ~fit, the model written atomically on ~save. Segments: the
/// template's fit.lines (the `line` channel), fit.windows (tt), the ~start_segment /
/// ~stop_segment services, or the maneuvers the INS rates show (~auto_segments). Publishes
/// ~calibration_status at 1 Hz. Parameters: config/calibrator.yaml.
class CalibratorRos {
 public:
  CalibratorRos(ros::NodeHandle nh, ros::NodeHandle pnh);

 private:
  void add(const AlignedSample& a);
  bool in_segment(double t) const;
  void on_imu(const sensor_msgs::Imu::ConstPtr& m);
  void publish_status();
  bool on_start(std_srvs::Trigger::Request&, std_srvs::Trigger::Response& res);
  bool on_stop(std_srvs::Trigger::Request&, std_srvs::Trigger::Response& res);
  bool on_fit(std_srvs::Trigger::Request&, std_srvs::Trigger::Response& res);
  bool on_save(std_srvs::Trigger::Request&, std_srvs::Trigger::Response& res);
  bool on_reset(std_srvs::Trigger::Request&, std_srvs::Trigger::Response& res);
  void diagnose(diagnostic_updater::DiagnosticStatusWrapper& stat);

  ros::NodeHandle nh_, pnh_;
  std::string out_path_;
  bool auto_segments_ = false, manual_segment_ = false, ending_ = false;
  std::unique_ptr<InflightCalibrator> calibrator_;
  std::unique_ptr<Model> fitted_;
  std::unique_ptr<InputStream> input_;
  ManeuverDetector detector_;
  std::deque<std::pair<double, bool>> maneuver_;  // the detector's verdicts by data time
  ros::Subscriber sub_imu_;
  ros::Publisher pub_status_;
  ros::ServiceServer srv_start_, srv_stop_, srv_fit_, srv_save_, srv_reset_;
  ros::WallTimer status_timer_, process_timer_, diag_timer_;
  diagnostic_updater::Updater updater_;
};

}  // namespace magcomp::rosio
