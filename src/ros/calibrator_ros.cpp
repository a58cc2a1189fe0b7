// magcomp ROS layer: the in-flight calibrator: parameters -> aligned inputs -> calibration.
#include "magcomp/ros/calibrator_ros.h"

#include <magcomp/CalibrationStatus.h>

#include <algorithm>
#include <cmath>
#include <set>

#include "magcomp/core/error.h"
#include "magcomp/core/io/time_base.h"
#include "magcomp/ros/params.h"

namespace magcomp::rosio {
namespace {

const std::set<std::string> kCalibratorParams = with_input_params(
    {"calibration_model", "calibration_out", "forgetting", "auto_segments", "imu_topic"});

constexpr double kStatusPeriod_s = 1.0;
constexpr double kProcessPeriod_s = 0.25;  // held inputs are let out in wall time too
constexpr size_t kMaxVerdicts = 100000;    // the maneuver detector's verdicts kept
constexpr double kLineTolerance = 1e-6;    // line numbers compare to this

}  // namespace

CalibratorRos::CalibratorRos(ros::NodeHandle nh, ros::NodeHandle pnh)
    : nh_(nh), pnh_(pnh), updater_(nh, pnh) {
  warn_unknown_params(pnh_, kCalibratorParams);
  std::string template_path;
  pnh_.param<std::string>("calibration_model", template_path, "");
  if (template_path.empty()) {
    reject_param("calibration_model", "required (a model template: terms and fit settings)");
  }
  pnh_.param<std::string>("calibration_out", out_path_, "");
  double forgetting = 1.0;
  pnh_.param("forgetting", forgetting, 1.0);
  try {
    calibrator_ = std::make_unique<InflightCalibrator>(load_model_yaml(template_path), forgetting);
  } catch (const std::exception& e) {
    reject_param("calibration_model", e.what());
  }
  pnh_.param("auto_segments", auto_segments_, false);
  const Model& m = calibrator_->model();
  const InputParams in = read_input_params(pnh_, m.scalar, m.vector);
  InputStream::Callbacks cb;
  auto process = [this] {
    input_->aligner().process(ros::WallTime::now().toSec(), ending_, false,
                              [this](const AlignedSample& s) { add(s); });
  };
  cb.changed = process;
  cb.jumped_back = [this] {  // a replay starting over must not count twice
    calibrator_->reset();
    detector_.reset();
    maneuver_.clear();
  };
  cb.ended = [this, process](double) {
    ending_ = true;
    process();
  };
  input_ = std::make_unique<InputStream>(nh_, in.topics, in.aligner,
                                         static_cast<uint32_t>(in.queue_size), in.tcp_nodelay,
                                         in.base_frame, cb);
  // Each sample carries the template's channels, then `line` (a selection by line needs that
  // very sample's line: the sample waits for its aux message).
  std::vector<std::string> channels = calibrator_->channels();
  channels.push_back("line");
  input_->aligner().select_channels(channels);
  input_->aligner().wait_for(!calibrator_->channels().empty() || !m.fit.lines.empty(), false);
  if (auto_segments_) {
    std::string imu_topic;
    pnh_.param<std::string>("imu_topic", imu_topic, "magcomp/ins/imu");
    sub_imu_ =
        nh_.subscribe(imu_topic, static_cast<uint32_t>(in.queue_size), &CalibratorRos::on_imu, this,
                      ros::TransportHints().tcpNoDelay(in.tcp_nodelay));
  }
  pub_status_ = pnh_.advertise<magcomp::CalibrationStatus>("calibration_status", 10, true);
  srv_start_ = pnh_.advertiseService("start_segment", &CalibratorRos::on_start, this);
  srv_stop_ = pnh_.advertiseService("stop_segment", &CalibratorRos::on_stop, this);
  srv_fit_ = pnh_.advertiseService("fit", &CalibratorRos::on_fit, this);
  srv_save_ = pnh_.advertiseService("save", &CalibratorRos::on_save, this);
  srv_reset_ = pnh_.advertiseService("reset_calibration", &CalibratorRos::on_reset, this);
  status_timer_ = nh_.createWallTimer(ros::WallDuration(kStatusPeriod_s),
                                      [this](const ros::WallTimerEvent&) { publish_status(); });
  process_timer_ = nh_.createWallTimer(ros::WallDuration(kProcessPeriod_s),
                                       [process](const ros::WallTimerEvent&) { process(); });
  updater_.setHardwareID("magcomp calibrator: " + m.scalar + " with " + m.vector);
  updater_.add("calibrator", this, &CalibratorRos::diagnose);
  diag_timer_ =
      nh_.createWallTimer(ros::WallDuration(kStatusPeriod_s),
                          [this](const ros::WallTimerEvent&) { updater_.force_update(); });
  ROS_INFO("magcomp calibrator: %s with %s, template %s", m.scalar.c_str(), m.vector.c_str(),
           template_path.c_str());
}

bool CalibratorRos::in_segment(double t) const {
  if (manual_segment_) return true;
  if (auto_segments_ && !maneuver_.empty()) {  // the detector's latest verdict at or before t
    auto it =
        std::upper_bound(maneuver_.begin(), maneuver_.end(), t,
                         [](double x, const std::pair<double, bool>& v) { return x < v.first; });
    if (it != maneuver_.begin() && (it - 1)->second) return true;
  }
  const FitSettings& fs = calibrator_->model().fit;
  if (!fs.windows.empty()) {
    const ros::Time st = input_->stamp(t);
    const double tt = tt_of(st.sec, st.nsec);
    for (const auto& w : fs.windows)
      if (tt >= w.start_s && tt <= w.end_s) return true;
  }
  return false;
}

void CalibratorRos::add(const AlignedSample& a) {
  StreamSample s;
  s.t_s = a.t_s;
  s.scalar_nT = a.scalar_nT;
  s.vector_nT = a.vector_nT;
  s.channels.assign(a.channels.begin(), a.channels.end() - 1);
  const double line = a.channels.back();
  bool in = in_segment(a.t_s);
  for (double l : calibrator_->model().fit.lines) in = in || std::abs(line - l) < kLineTolerance;
  calibrator_->add(s, in);
}

void CalibratorRos::on_imu(const sensor_msgs::Imu::ConstPtr& m) {
  // base_link (FLU) body rates -> MIT convention (pitch nose up, yaw clockwise), deg/s.
  const double t = input_->rel(m->header.stamp);
  const bool on =
      detector_.update(t, -m->angular_velocity.y * kRadToDeg, m->angular_velocity.x * kRadToDeg,
                       -m->angular_velocity.z * kRadToDeg);
  if (!maneuver_.empty() && t <= maneuver_.back().first) return;
  maneuver_.emplace_back(t, on);
  while (maneuver_.size() > kMaxVerdicts) maneuver_.pop_front();
}

void CalibratorRos::publish_status() {
  magcomp::CalibrationStatus st;
  st.header.stamp = input_->stamp(std::max(input_->aligner().last_scalar_t(), 0.0));
  const Model m = fitted_ ? *fitted_ : calibrator_->rls();
  st.state = fitted_ ? "fitted" : (calibrator_->samples() > 0 ? "collecting" : "idle");
  st.segments = static_cast<uint32_t>(calibrator_->segments());
  st.samples = static_cast<uint32_t>(calibrator_->samples());
  st.condition_number = fitted_ ? fitted_->report.condition_number : NAN;
  st.residual_std_nT = fitted_ ? fitted_->report.residual_std_nT : NAN;
  st.column_names = m.column_names;
  st.coefficients.assign(m.coefficients.data(), m.coefficients.data() + m.coefficients.size());
  pub_status_.publish(st);
}

bool CalibratorRos::on_start(std_srvs::Trigger::Request&, std_srvs::Trigger::Response& res) {
  manual_segment_ = true;
  res.success = true;
  res.message = "collecting";
  return true;
}

bool CalibratorRos::on_stop(std_srvs::Trigger::Request&, std_srvs::Trigger::Response& res) {
  manual_segment_ = false;
  calibrator_->end_segment();
  res.success = true;
  res.message = std::to_string(calibrator_->segments()) + " segments";
  return true;
}

bool CalibratorRos::on_fit(std_srvs::Trigger::Request&, std_srvs::Trigger::Response& res) {
  try {
    fitted_ = std::make_unique<Model>(calibrator_->batch());
    res.success = true;
    res.message = "fitted on " + std::to_string(fitted_->report.samples) + " samples in " +
                  std::to_string(fitted_->report.segments) + " segments, condition number " +
                  std::to_string(fitted_->report.condition_number);
  } catch (const std::exception& e) {
    res.success = false;
    res.message = e.what();
  }
  publish_status();
  return true;
}

bool CalibratorRos::on_save(std_srvs::Trigger::Request& req, std_srvs::Trigger::Response& res) {
  if (out_path_.empty()) {
    res.success = false;
    res.message = "~calibration_out: not set";
    return true;
  }
  if (!fitted_ && (on_fit(req, res), !res.success)) return true;
  try {
    save_model_yaml(*fitted_, out_path_);  // atomic: a compensator watching it reloads
    res.success = true;
    res.message = "wrote " + out_path_;
  } catch (const std::exception& e) {
    res.success = false;
    res.message = e.what();
  }
  return true;
}

bool CalibratorRos::on_reset(std_srvs::Trigger::Request&, std_srvs::Trigger::Response& res) {
  calibrator_->reset();
  fitted_.reset();
  manual_segment_ = false;
  res.success = true;
  res.message = "reset";
  publish_status();
  return true;
}

void CalibratorRos::diagnose(diagnostic_updater::DiagnosticStatusWrapper& stat) {
  const AlignerCounts& c = input_->aligner().counts();
  stat.summary(diagnostic_msgs::DiagnosticStatus::OK,
               fitted_ ? "fitted" : (calibrator_->samples() > 0 ? "collecting" : "idle"));
  stat.add("calibration_segments", calibrator_->segments());
  stat.add("calibration_samples", static_cast<long>(calibrator_->samples()));
  stat.add("calibration_rls_updates", static_cast<long>(calibrator_->rls_updates()));
  stat.add("scalar_in", c.scalar_in);
  stat.add("stale_inputs_held", c.stale_inputs_held);
  stat.add("late_inputs_dropped", c.late_inputs);
  stat.add("time_jumps_back", c.jumps_back);
  stat.add("gaps", c.gaps);
}

}  // namespace magcomp::rosio
