// magcomp ROS layer: compensator node class.
#include "magcomp/ros/compensator_ros.h"

#include <magcomp/CompensatedField.h>
#include <sys/stat.h>
#include <visualization_msgs/MarkerArray.h>

#include <Eigen/Geometry>
#include <algorithm>
#include <cmath>
#include <set>

#include "magcomp/core/error.h"
#include "magcomp/core/igrf.h"
#include "magcomp/ros/params.h"

namespace magcomp::rosio {
namespace {

double file_mtime(const std::string& path) {
  struct stat st {};
  if (::stat(path.c_str(), &st) != 0) return 0.0;
  return static_cast<double>(st.st_mtim.tv_sec) + 1e-9 * static_cast<double>(st.st_mtim.tv_nsec);
}

const std::set<std::string> kKnownParams = {
    "model_path",      "scalar_topic",      "vector_topic",    "aux_topic",     "fix_topic",
    "reference_topic", "output_topic",      "frame_id",        "max_gap_s",     "max_wait_s",
    "jump_back_s",     "buffer_s",          "watch_model",     "marker_stride", "expected_rate_hz",
    "flush_after_s",   "calibration_model", "calibration_out", "forgetting",    "auto_segments",
    "imu_topic",       "base_frame",        "tcp_nodelay",     "queue_size",    "end_of_stream_topic",
    "publish_track_tf"};
constexpr long kTrackTfEvery = 5;  // outputs between two poses of the aircraft on the track

}  // namespace

template <typename T>
bool CompensatorRos::interpolate(const std::deque<T>& buf, double t, T* out) {
  if (buf.empty() || t > buf.back().t || t < buf.front().t) return false;
  auto hi =
      std::lower_bound(buf.begin(), buf.end(), t, [](const T& a, double x) { return a.t < x; });
  if (hi->t == t) {
    *out = *hi;
    return true;
  }
  auto lo = hi - 1;
  const double w = (t - lo->t) / (hi->t - lo->t);
  *out = *lo;
  out->t = t;
  if constexpr (std::is_same_v<T, Timed3> || std::is_same_v<T, Timed1>) {
    out->v = (1 - w) * lo->v + w * hi->v;
  } else {
    for (size_t k = 0; k < out->v.size(); ++k) out->v[k] = (1 - w) * lo->v[k] + w * hi->v[k];
  }
  return true;
}

double CompensatorRos::rel(const ros::Time& s) {
  if (base_sec_ < 0) base_sec_ = s.sec;
  return static_cast<double>(static_cast<int64_t>(s.sec) - base_sec_) + 1e-9 * s.nsec;
}

ros::Time CompensatorRos::stamp(double t) const {
  const double whole = std::floor(t);
  int64_t nsec = std::llround((t - whole) * 1e9);
  const int64_t sec =
      std::max<int64_t>(0, base_sec_) + static_cast<int64_t>(whole) + nsec / 1000000000LL;
  nsec %= 1000000000LL;
  ros::Time out;
  out.sec = static_cast<uint32_t>(sec);
  out.nsec = static_cast<uint32_t>(nsec);
  return out;
}

CompensatorRos::CompensatorRos(ros::NodeHandle nh, ros::NodeHandle pnh)
    : nh_(nh), pnh_(pnh), updater_(nh, pnh) {
  warn_unknown_params(pnh_, kKnownParams);  // typos are not silently ignored
  std::string calibration_model;
  pnh_.param<std::string>("calibration_model", calibration_model, "");
  pnh_.param<std::string>("calibration_out", calibration_out_, "");
  double forgetting = 1.0;
  pnh_.param("forgetting", forgetting, 1.0);
  if (!calibration_model.empty()) {
    try {
      calibration_template_ = std::make_unique<Model>(load_model_yaml(calibration_model));
      calibrator_ = std::make_unique<InflightCalibrator>(*calibration_template_, forgetting);
    } catch (const std::exception& e) {
      reject_param("calibration_model", e.what());
    }
  }
  pnh_.param<std::string>("model_path", model_path_, "");
  if (model_path_.empty() && !calibrator_) {
    reject_param("model_path", "required (a fitted model YAML written by magcomp calibrate)");
  }
  pnh_.param("max_gap_s", max_gap_s_, 1.0);
  pnh_.param("max_wait_s", max_wait_s_, 0.5);
  pnh_.param("jump_back_s", jump_back_s_, 1.0);
  pnh_.param("buffer_s", buffer_s_, 10.0);
  pnh_.param("watch_model", watch_model_, true);
  pnh_.param("marker_stride", marker_stride_, 10);
  pnh_.param("flush_after_s", flush_after_s_, 1.0);
  pnh_.param<std::string>("frame_id", frame_id_, "magcomp_track");
  pnh_.param("publish_track_tf", publish_track_tf_, false);
  double rate = 10.0;
  pnh_.param("expected_rate_hz", rate, 10.0);
  auto positive = [](double v, const char* key) {
    if (!(v > 0)) {
      reject_param(key, "must be > 0 (s or Hz), got " + std::to_string(v));
    }
  };
  positive(max_gap_s_, "max_gap_s");
  positive(max_wait_s_, "max_wait_s");
  positive(jump_back_s_, "jump_back_s");
  positive(buffer_s_, "buffer_s");
  if (!(flush_after_s_ >= 0)) {
    reject_param("flush_after_s", "must be >= 0 s (0: only on the end-of-stream topic), got " +
                                      std::to_string(flush_after_s_));
  }
  positive(rate, "expected_rate_hz");
  if (marker_stride_ < 1) reject_param("marker_stride", "must be >= 1 (outputs per track point)");
  track_ = std::make_unique<TrackMarker>(frame_id_, marker_stride_);
  min_freq_ = 0.5 * rate;
  max_freq_ = 2.0 * rate;
  if (!model_path_.empty() && !load_model("start-up")) ROS_ERROR("%s", model_error_.c_str());
  const Model* sensors = comp_ ? &comp_->model() : calibration_template_.get();
  const std::string scalar = sensors ? sensors->scalar : "mag_5_uc";
  const std::string vector = sensors ? sensors->vector : "flux_c";
  std::string scalar_topic, vector_topic, aux_topic, fix_topic, ref_topic, out_topic;
  // Defaults are relative: a namespaced launch moves them all (magcomp convert's bags, played in
  // the root namespace, use these names).
  pnh_.param<std::string>("scalar_topic", scalar_topic, "magcomp/scalar/" + scalar);
  pnh_.param<std::string>("vector_topic", vector_topic, "magcomp/fluxgate/" + vector);
  pnh_.param<std::string>("aux_topic", aux_topic, "magcomp/aux");
  pnh_.param<std::string>("fix_topic", fix_topic, "magcomp/ins/fix");
  pnh_.param<std::string>("reference_topic", ref_topic, "");
  pnh_.param<std::string>("output_topic", out_topic, "magcomp/compensated");
  // Deep enough that a fast replay's bursts are never dropped by the transport.
  pub_out_ = nh_.advertise<magcomp::CompensatedField>(out_topic, 10000);
  pub_marker_ = nh_.advertise<visualization_msgs::MarkerArray>(out_topic + "/track", 2, true);
  // TCP_NODELAY (default): lowest latency in flight. false: Nagle batches a flood of small
  // messages (a bag played as fast as possible) into fewer packets and wake-ups.
  bool nodelay = true;
  pnh_.param("tcp_nodelay", nodelay, true);
  const ros::TransportHints hints = ros::TransportHints().tcpNoDelay(nodelay);
  // Input queues: deep enough for a bag played with --immediate (roscpp drops the oldest message
  // of a full queue without a word, so this is a parameter).
  int queue = 1000;
  pnh_.param("queue_size", queue, 1000);
  if (queue < 1) {
    reject_param("queue_size", "must be >= 1, got " + std::to_string(queue));
  }
  const auto q = static_cast<uint32_t>(queue);
  sub_scalar_ = nh_.subscribe(scalar_topic, q, &CompensatorRos::on_scalar, this, hints);
  sub_vector_ = nh_.subscribe(vector_topic, q, &CompensatorRos::on_vector, this, hints);
  sub_aux_ = nh_.subscribe(aux_topic, q, &CompensatorRos::on_aux, this, hints);
  sub_fix_ = nh_.subscribe(fix_topic, q, &CompensatorRos::on_fix, this, hints);
  if (!ref_topic.empty()) {
    sub_ref_ = nh_.subscribe(ref_topic, q, &CompensatorRos::on_reference, this, hints);
  }
  std::string end_topic;
  pnh_.param<std::string>("end_of_stream_topic", end_topic, "magcomp/end_of_stream");
  if (!end_topic.empty()) {
    sub_end_ = nh_.subscribe(end_topic, 10, &CompensatorRos::on_end_of_stream, this);
  }
  srv_reload_ = pnh_.advertiseService("reload", &CompensatorRos::on_reload, this);
  pnh_.param<std::string>("base_frame", base_frame_, "base_link");
  tf_buffer_ = std::make_unique<tf2_ros::Buffer>();
  if (publish_track_tf_) tf_broadcaster_ = std::make_unique<tf2_ros::TransformBroadcaster>();
  tf_listener_ = std::make_unique<tf2_ros::TransformListener>(*tf_buffer_, nh_);
  pnh_.param("auto_segments", auto_segments_, false);
  if (calibrator_ && auto_segments_) {
    std::string imu_topic;
    pnh_.param<std::string>("imu_topic", imu_topic, "magcomp/ins/imu");
    sub_imu_ = nh_.subscribe(imu_topic, 1000, &CompensatorRos::on_imu, this, hints);
  }
  if (calibrator_) {
    pub_status_ = pnh_.advertise<magcomp::CalibrationStatus>("calibration_status", 10, true);
    srv_start_ = pnh_.advertiseService("start_segment", &CompensatorRos::on_start_segment, this);
    srv_stop_ = pnh_.advertiseService("stop_segment", &CompensatorRos::on_stop_segment, this);
    srv_fit_ = pnh_.advertiseService("fit", &CompensatorRos::on_fit, this);
    srv_save_ = pnh_.advertiseService("save", &CompensatorRos::on_save, this);
    srv_reset_ =
        pnh_.advertiseService("reset_calibration", &CompensatorRos::on_reset_calibration, this);
    status_timer_ = nh_.createWallTimer(ros::WallDuration(1.0), [this](const ros::WallTimerEvent&) {
      publish_calibration_status();
    });
  }
  // Wall timers: the model file and the end of a replay happen in wall time, not data time.
  watch_timer_ = nh_.createWallTimer(ros::WallDuration(0.25), [this](const ros::WallTimerEvent&) {
    if (watch_model_) on_watch(ros::TimerEvent());
    process_ready(false);  // inputs that never came: hold the latest once max_wait_s has passed
    finish_end_of_stream();
    // No scalar for flush_after_s of wall time (sensor stopped, bag finished without an end
    // message): emit what is pending instead of keeping it. Remembered: if the stream goes on,
    // those outputs were premature and that is counted.
    if (flush_after_s_ > 0 && (ros::WallTime::now() - last_scalar_wall_).toSec() > flush_after_s_ &&
        (!pending_scalar_.empty() || (comp_ && comp_->pending() > 0))) {
      flushed_at_t_ = last_scalar_t_;
      flush_all();
    }
  });
  updater_.setHardwareID("magcomp compensator: " + scalar + " with " + vector);
  updater_.add("compensator", this, &CompensatorRos::diagnose);
  freq_ = std::make_unique<diagnostic_updater::FrequencyStatus>(
      diagnostic_updater::FrequencyStatusParam(&min_freq_, &max_freq_, 0.1, 10));
  updater_.add(*freq_);
  diag_timer_ = nh_.createWallTimer(
      ros::WallDuration(1.0), [this](const ros::WallTimerEvent&) { updater_.force_update(); });
  ROS_INFO("magcomp compensator: %s -> %s (model %s)", scalar_topic.c_str(), out_topic.c_str(),
           model_path_.c_str());
}

std::vector<int> CompensatorRos::channel_indices(const std::vector<std::string>& names) const {
  std::vector<int> idx;
  for (const auto& n : names) {
    auto it = std::find(aux_all_names_.begin(), aux_all_names_.end(), n);
    idx.push_back(it == aux_all_names_.end() ? -1 : static_cast<int>(it - aux_all_names_.begin()));
  }
  return idx;
}

std::vector<double> CompensatorRos::channels_at(double t, const std::vector<int>& index) {
  std::vector<double> out(index.size(), NAN);
  TimedValues a{};
  const bool ok = interpolate(aux_, t, &a) || (!aux_.empty() && (a = aux_.back(), true));
  if (!ok) return out;
  for (size_t k = 0; k < index.size(); ++k) {
    if (index[k] >= 0 && static_cast<size_t>(index[k]) < a.v.size())
      out[k] = a.v[static_cast<size_t>(index[k])];
  }
  return out;
}

bool CompensatorRos::load_model(const std::string& why) {
  try {
    Model m = load_model_yaml(model_path_);
    auto next = std::make_unique<StreamingCompensator>(std::move(m));
    const double mtime = file_mtime(model_path_);
    if (comp_) {
      if (next->model().scalar != comp_->model().scalar ||
          next->model().vector != comp_->model().vector) {
        model_error_ =
            model_path_ + ": the new model's sensors differ from the subscribed ones; not swapped";
        return false;
      }
      // Swap without losing a sample: the new model re-reads the recent samples and takes over
      // at the first stamp not yet published.
      const std::vector<int> idx = channel_indices(next->required_channels());
      for (StreamSample s : history_) {
        s.channels = channels_at(s.t_s, idx);
        if (next->needs_igrf()) s.igrf_nT = igrf_at(s.t_s);
        for (const auto& o : next->push(s)) {
          if (o.t_s > last_published_t_) publish(o);
        }
      }
      ++n_reloads_;
      ROS_INFO("magcomp: model reloaded (%s): terms now %zu, takes effect after t = %.3f",
               why.c_str(), next->model().terms.size(), last_published_t_);
    }
    comp_ = std::move(next);
    channel_index_ = channel_indices(comp_->required_channels());
    model_mtime_ = mtime;
    model_error_.clear();
    return true;
  } catch (const std::exception& e) {
    model_error_ = e.what();
    model_mtime_ = file_mtime(model_path_);
    return false;
  }
}

bool CompensatorRos::on_reload(std_srvs::Trigger::Request&, std_srvs::Trigger::Response& res) {
  res.success = load_model("service");
  res.message = res.success ? "reloaded " + model_path_ : model_error_;
  return true;
}

void CompensatorRos::on_watch(const ros::TimerEvent&) {
  const double m = file_mtime(model_path_);
  if (m != 0.0 && m != model_mtime_) {
    if (!load_model("file changed")) ROS_ERROR("magcomp: %s", model_error_.c_str());
  }
}

void CompensatorRos::reset_streams(const char* why) {
  if (comp_) {
    for (const auto& o : comp_->flush()) publish(o);
    comp_->reset();
  }
  history_.clear();
  ROS_WARN("magcomp: %s: compensator restarted", why);
}

void CompensatorRos::flush_all() {
  process_ready(true);
  if (comp_) {
    for (const auto& o : comp_->flush()) publish(o);
    history_.clear();
  }
}

void CompensatorRos::on_end_of_stream(const std_msgs::Time::ConstPtr& m) {
  ROS_INFO("magcomp: end of stream at data time %.3f s: %zu samples pending", m->data.toSec(),
           pending_scalar_.size() + (comp_ ? comp_->pending() : 0));
  ending_ = true;
  process_ready(false);
  finish_end_of_stream();
}

void CompensatorRos::finish_end_of_stream() {
  if (!ending_ || !pending_scalar_.empty()) return;
  ending_ = false;
  if (comp_) {
    for (const auto& o : comp_->flush()) publish(o);
    history_.clear();
  }
}

void CompensatorRos::on_scalar(const magcomp::ScalarMagnetometer::ConstPtr& m) {
  const double t = rel(m->header.stamp);
  ++n_in_;
  ending_ = false;  // a new stream after an end message (a bag played again)
  if (std::isfinite(flushed_at_t_)) {
    if (t > flushed_at_t_ && t - flushed_at_t_ <= max_gap_s_) {
      ++n_premature_flushes_;
      ROS_WARN("magcomp: the input stalled for more than flush_after_s (%.2f s of wall time) and "
               "then went on at data time %.3f s: the samples before it were flushed without "
               "their successors (premature_flushes)",
               flush_after_s_, t);
    }
    flushed_at_t_ = NAN;
  }
  if (t == last_scalar_t_) {
    ++n_dup_;
    return;
  }
  if (t < last_scalar_t_) {
    if (last_scalar_t_ - t > jump_back_s_) {  // e.g. a bag played in a loop: start again
      ++n_jumps_;
      pending_scalar_.clear();
      reset_streams("time jumped back");
      vectors_.clear();
      aux_.clear();
      fixes_.clear();
      references_.clear();
      last_published_t_ = -1e300;
      if (track_) track_->clear();
      if (calibrator_) calibrator_->reset();  // a replay starting over must not count twice
      detector_.reset();
      maneuver_.clear();
    } else {
      ++n_out_of_order_;
      return;
    }
  }
  last_scalar_t_ = t;
  last_scalar_wall_ = ros::WallTime::now();
  if (!std::isfinite(m->field_nT)) ++n_nan_;
  pending_scalar_.push_back({t, m->field_nT, ros::WallTime::now().toSec()});
  process_ready(false);
}

template <typename T>
bool CompensatorRos::append(std::deque<T>& buf, T item, long* late) {
  const double t = item.t;
  if (!buf.empty() && t <= buf.back().t) {
    if (buf.back().t - t <= jump_back_s_) {
      if (late) ++*late;
      return false;
    }
    buf.clear();
  }
  buf.push_back(std::move(item));
  while (buf.size() > 2 && buf.front().t < t - buffer_s_) buf.pop_front();
  return true;
}

void CompensatorRos::on_vector(const sensor_msgs::MagneticField::ConstPtr& m) {
  const double t = rel(m->header.stamp);
  Eigen::Vector3d b(m->magnetic_field.x, m->magnetic_field.y, m->magnetic_field.z);
  // A fluxgate mounted with a rotation: rotate into base_frame (its mount is static: look it up
  // once; until it is known the vector is used as is and counted).
  const std::string& frame = m->header.frame_id;
  if (!frame.empty() && frame != base_frame_) {
    const bool need_lookup = !rotation_known_ || frame != vector_frame_;
    const double now = need_lookup ? ros::WallTime::now().toSec() : 0.0;
    if (need_lookup && now - last_tf_try_wall_ > 0.2) {
      last_tf_try_wall_ = now;  // a missing mount is retried 5 times a second, not per message
      try {
        const geometry_msgs::TransformStamped tf =
            tf_buffer_->lookupTransform(base_frame_, frame, ros::Time(0));
        const auto& q = tf.transform.rotation;
        vector_rotation_ = Eigen::Quaterniond(q.w, q.x, q.y, q.z).toRotationMatrix();
        vector_frame_ = frame;
        rotation_known_ = true;
      } catch (const tf2::TransformException& e) {
        ROS_WARN_THROTTLE(10, "magcomp: no tf2 %s <- %s yet (%s): fluxgate used as is",
                          base_frame_.c_str(), frame.c_str(), e.what());
      }
    }
    if (rotation_known_ && frame == vector_frame_) {
      b = vector_rotation_ * b;
    } else {
      ++n_no_tf_;
    }
  }
  if (!append(vectors_, Timed3{t, b * 1e9}, &n_late_inputs_)) return;  // REP 145 Tesla -> nT
  last_vector_t_ = t;
  process_ready(false);
}

void CompensatorRos::on_aux(const magcomp::AuxChannels::ConstPtr& m) {
  const double t = rel(m->header.stamp);
  if (m->values.size() != m->names.size()) {  // which value is which cannot be known: dropped
    ++n_aux_mismatch_;
    ROS_WARN_THROTTLE(10, "magcomp: an AuxChannels message has %zu names and %zu values: dropped",
                      m->names.size(), m->values.size());
    return;
  }
  if (m->names != aux_all_names_) {  // a new channel list: re-index (older values are dropped)
    aux_all_names_ = m->names;
    aux_.clear();
    if (comp_) channel_index_ = channel_indices(comp_->required_channels());
    diurnal_index_ = channel_indices({"diurnal"})[0];
    line_index_ = channel_indices({"line"})[0];
    if (calibration_template_) {
      std::vector<std::string> names;
      for (const auto& term : calibration_template_->make_terms()) {
        for (const auto& f : term->required_fields()) names.push_back(f);
      }
      calibration_index_ = channel_indices(names);
    }
  }
  TimedValues tv{t, m->values};
  tv.v.resize(aux_all_names_.size(), NAN);
  if (append(aux_, std::move(tv), &n_late_inputs_)) process_ready(false);
}

void CompensatorRos::on_fix(const sensor_msgs::NavSatFix::ConstPtr& m) {
  append(fixes_,
         Timed3{rel(m->header.stamp), Eigen::Vector3d(m->latitude, m->longitude, m->altitude)},
         &n_late_inputs_);
}

void CompensatorRos::on_imu(const sensor_msgs::Imu::ConstPtr& m) {
  // base_link (FLU) body rates -> MIT convention (pitch nose up, yaw clockwise), deg/s.
  const double t = rel(m->header.stamp);
  constexpr double kDegPerRad = 180.0 / M_PI;
  const bool on =
      detector_.update(t, -m->angular_velocity.y * kDegPerRad, m->angular_velocity.x * kDegPerRad,
                       -m->angular_velocity.z * kDegPerRad);
  append(maneuver_, Timed1{t, on ? 1.0 : 0.0}, nullptr);
}

void CompensatorRos::on_reference(const magcomp::ScalarMagnetometer::ConstPtr& m) {
  append(references_, Timed1{rel(m->header.stamp), m->field_nT}, &n_late_inputs_);
}

void CompensatorRos::process_ready(bool force) {
  if (!comp_ && !calibrator_) {
    pending_scalar_.clear();
    return;
  }
  // Wait for the aux message of a stamp when the model or the calibration needs a channel from it
  // (a calibration selected by line needs the `line` of that very sample).
  const bool need_aux =
      !channel_index_.empty() ||
      (calibrator_ && (!calibration_index_.empty() || !calibration_template_->fit.lines.empty()));
  // A neural stage that removes the core field needs the position of that very sample.
  const bool need_fix = comp_ && comp_->needs_igrf();
  while (!pending_scalar_.empty()) {
    const auto [t, value, arrived_wall] = pending_scalar_.front();
    const bool covered = !vectors_.empty() && vectors_.back().t >= t &&
                         (!need_aux || (!aux_.empty() && aux_.back().t >= t)) &&
                         (!need_fix || (!fixes_.empty() && fixes_.back().t >= t));
    // Hold the latest inputs only after waiting max_wait_s in data time AND in wall time (on a fast
    // replay data time runs ahead of the transport; in real time the two agree).
    // After the end-of-stream message no later scalar will come: the wall time alone decides.
    const bool waited_enough = (ending_ || last_scalar_t_ - t > max_wait_s_) &&
                               ros::WallTime::now().toSec() - arrived_wall > max_wait_s_;
    if (!covered && !waited_enough && !force) return;
    pending_scalar_.pop_front();
    StreamSample s;
    s.t_s = t;
    s.scalar_nT = value;
    Timed3 v{};
    if (interpolate(vectors_, t, &v)) {
      s.vector_nT = v.v;
    } else if (!vectors_.empty()) {
      s.vector_nT = vectors_.back().v;  // waited max_wait_s: hold the latest, and say so
      ++n_stale_;
    } else {
      s.vector_nT.setConstant(NAN);
      ++n_stale_;
    }
    s.channels = channels_at(t, channel_index_);
    if (need_fix) s.igrf_nT = igrf_at(t);
    if (!history_.empty() && t - history_.back().t_s > max_gap_s_) {
      ++n_gaps_;
      reset_streams("gap in the scalar stamps");
    }
    feed(s);
  }
}

void CompensatorRos::feed(const StreamSample& s) {
  if (calibrator_) calibrate(s);
  if (!comp_) return;
  history_.push_back(s);
  // Enough recent samples for a swapped-in model to fill its lookahead and a neural window.
  while (history_.size() >
         static_cast<size_t>(std::max(4 * std::max(comp_->lookahead(), 3) + 4, 256)))
    history_.pop_front();
  for (const auto& o : comp_->push(s)) publish(o);
}

double CompensatorRos::igrf_at(double t) {
  Timed3 fix{};
  if (!interpolate(fixes_, t, &fix)) return NAN;
  try {
    const boost::posix_time::ptime p = stamp(t).toBoost();
    const double year = decimal_year(p.date().year(), p.date().day_of_year(),
                                     p.time_of_day().total_microseconds() * 1e-6);
    return Igrf::shipped().geodetic(fix.v.x(), fix.v.y(), fix.v.z(), year).total_nT();
  } catch (const std::exception& e) {
    ROS_WARN_THROTTLE(10, "magcomp: no IGRF at the sample: %s", e.what());
    return NAN;
  }
}

void CompensatorRos::publish(const StreamOutput& o) {
  if (o.t_s <= last_published_t_) return;
  last_published_t_ = o.t_s;
  // Published as a shared pointer: a subscriber in the same nodelet manager gets it without a copy.
  const auto out = boost::make_shared<magcomp::CompensatedField>();
  magcomp::CompensatedField& msg = *out;
  msg.header.stamp = stamp(o.t_s);
  msg.header.frame_id = comp_ ? comp_->model().scalar.substr(0, 5) : "";
  msg.measured_nT = o.measured_nT;
  msg.aircraft_correction_nT = o.correction_nT;
  msg.compensated_nT = o.compensated_nT;
  msg.variance_nT2 = o.variance_nT2;
  msg.anomaly_nT = NAN;
  double diurnal = 0.0;
  if (diurnal_index_ >= 0) {
    const double d = channels_at(o.t_s, {diurnal_index_})[0];
    if (std::isfinite(d)) diurnal = d;
  }
  // A neural stage already needed IGRF at this sample's input; otherwise compute it here.
  const double igrf = std::isfinite(o.igrf_nT) ? o.igrf_nT : igrf_at(o.t_s);
  if (std::isfinite(igrf)) msg.anomaly_nT = o.compensated_nT - igrf - diurnal;
  msg.reference_nT = NAN;
  msg.error_nT = NAN;
  Timed1 ref{};
  if (interpolate(references_, o.t_s, &ref)) {
    msg.reference_nT = ref.v;
    msg.error_nT = msg.compensated_nT - msg.reference_nT;
  }
  pub_out_.publish(boost::shared_ptr<const magcomp::CompensatedField>(out));
  ++n_out_;
  freq_->tick();
  // rviz: the track in a local east-north-up frame, coloured by the error (or the anomaly).
  Timed3 fix{};
  if (track_ && interpolate(fixes_, o.t_s, &fix)) {
    const bool due = track_->add(fix.v.x(), fix.v.y(), fix.v.z(),
                                 std::isfinite(msg.error_nT) ? msg.error_nT : msg.anomaly_nT);
    if (publish_track_tf_ && n_out_ % kTrackTfEvery == 0) {
      tf_broadcaster_->sendTransform(track_->pose(msg.header.stamp, base_frame_));
    }
    if (due && pub_marker_.getNumSubscribers() > 0) {
      pub_marker_.publish(track_->markers(msg.header.stamp));
    }
  }
}

void CompensatorRos::calibrate(const StreamSample& s) {
  StreamSample c = s;
  c.channels = channels_at(s.t_s, calibration_index_);
  // Segment membership: the services, or the template's fit.lines (the aux channel `line`) and
  // fit.windows (tt, seconds past midnight UTC of the stamp).
  bool in = manual_segment_;
  if (!in && auto_segments_ &&
      !maneuver_.empty()) {  // the detector's latest verdict at or before t
    auto it = std::upper_bound(maneuver_.begin(), maneuver_.end(), s.t_s,
                               [](double x, const Timed1& a) { return x < a.t; });
    in = it != maneuver_.begin() && (it - 1)->v > 0.5;
  }
  const FitSettings& fs = calibration_template_->fit;
  if (!in && !fs.lines.empty() && line_index_ >= 0) {
    const double line = channels_at(s.t_s, {line_index_})[0];
    for (double l : fs.lines) in = in || std::abs(line - l) < 1e-6;
  }
  if (!in && !fs.windows.empty()) {
    const ros::Time st = stamp(s.t_s);
    const double tt = static_cast<double>(st.sec % 86400) + 1e-9 * st.nsec;
    for (const auto& w : fs.windows) in = in || (tt >= w.start_s && tt <= w.end_s);
  }
  calibrator_->add(c, in);
}

void CompensatorRos::publish_calibration_status() {
  if (!calibrator_) return;
  magcomp::CalibrationStatus st;
  st.header.stamp = stamp(std::max(last_scalar_t_, 0.0));
  const Model m = calibrated_ ? *calibrated_ : calibrator_->rls();
  st.state = calibrated_ ? "fitted" : (calibrator_->samples() > 0 ? "collecting" : "idle");
  st.segments = static_cast<uint32_t>(calibrator_->segments());
  st.samples = static_cast<uint32_t>(calibrator_->samples());
  st.condition_number = calibrated_ ? calibrated_->report.condition_number : NAN;
  st.residual_std_nT = calibrated_ ? calibrated_->report.residual_std_nT : NAN;
  st.column_names = m.column_names;
  st.coefficients.assign(m.coefficients.data(), m.coefficients.data() + m.coefficients.size());
  pub_status_.publish(st);
}

bool CompensatorRos::on_start_segment(std_srvs::Trigger::Request&,
                                      std_srvs::Trigger::Response& res) {
  manual_segment_ = true;
  res.success = true;
  res.message = "collecting";
  return true;
}

bool CompensatorRos::on_stop_segment(std_srvs::Trigger::Request&,
                                     std_srvs::Trigger::Response& res) {
  manual_segment_ = false;
  calibrator_->end_segment();
  res.success = true;
  res.message = std::to_string(calibrator_->segments()) + " segments";
  return true;
}

bool CompensatorRos::on_fit(std_srvs::Trigger::Request&, std_srvs::Trigger::Response& res) {
  try {
    calibrated_ = std::make_unique<Model>(calibrator_->batch());
    res.success = true;
    res.message = "fitted on " + std::to_string(calibrated_->report.samples) + " samples in " +
                  std::to_string(calibrated_->report.segments) + " segments, condition number " +
                  std::to_string(calibrated_->report.condition_number);
  } catch (const std::exception& e) {
    res.success = false;
    res.message = e.what();
  }
  publish_calibration_status();
  return true;
}

bool CompensatorRos::on_save(std_srvs::Trigger::Request& req, std_srvs::Trigger::Response& res) {
  if (calibration_out_.empty()) {
    res.success = false;
    res.message = "~calibration_out: not set";
    return true;
  }
  if (!calibrated_ && (on_fit(req, res), !res.success)) return true;
  try {
    save_model_yaml(*calibrated_, calibration_out_);  // atomic; a compensator watching it reloads
    res.success = true;
    res.message = "wrote " + calibration_out_;
  } catch (const std::exception& e) {
    res.success = false;
    res.message = e.what();
  }
  return true;
}

bool CompensatorRos::on_reset_calibration(std_srvs::Trigger::Request&,
                                          std_srvs::Trigger::Response& res) {
  calibrator_->reset();
  calibrated_.reset();
  manual_segment_ = false;
  res.success = true;
  res.message = "reset";
  publish_calibration_status();
  return true;
}

void CompensatorRos::diagnose(diagnostic_updater::DiagnosticStatusWrapper& stat) {
  if (!comp_ && calibrator_) {
    stat.summary(diagnostic_msgs::DiagnosticStatus::OK, "calibrating (no model applied)");
  } else if (!comp_) {
    stat.summary(diagnostic_msgs::DiagnosticStatus::ERROR, "no model: " + model_error_);
  } else if (n_jumps_ + n_gaps_ + n_out_of_order_ + n_dup_ + n_nan_ + n_stale_ + n_late_inputs_ +
                 n_premature_flushes_ + n_aux_mismatch_ >
             0) {
    stat.summary(diagnostic_msgs::DiagnosticStatus::WARN,
                 "running; input faults seen (see counts)");
  } else {
    stat.summary(diagnostic_msgs::DiagnosticStatus::OK, "running");
  }
  stat.add("model_path", model_path_);
  stat.add("model_error", model_error_);
  if (comp_) {
    std::string terms;
    for (const auto& t : comp_->model().terms) terms += (terms.empty() ? "" : " ") + t;
    stat.add("terms", terms);
    stat.add("lookahead_samples", comp_->lookahead());
    const auto& nn = comp_->model().neural;
    stat.add("neural_stage", nn && nn->trained()
                                 ? nn->architecture + " (" + nn->mode + ", window " +
                                       std::to_string(nn->window) + ")"
                                 : std::string("none"));
  }
  stat.add("model_reloads", n_reloads_);
  stat.add("fluxgate_frame", vector_frame_.empty() ? std::string("(as given)") : vector_frame_);
  stat.add("fluxgate_vectors_without_tf", n_no_tf_);
  if (calibrator_) {
    stat.add("calibration_segments", calibrator_->segments());
    stat.add("calibration_samples", static_cast<long>(calibrator_->samples()));
    stat.add("calibration_rls_updates", static_cast<long>(calibrator_->rls_updates()));
  }
  stat.add("scalar_in", n_in_);
  stat.add("published", n_out_);
  stat.add("nan_scalar", n_nan_);
  stat.add("duplicate_stamps", n_dup_);
  stat.add("out_of_order_dropped", n_out_of_order_);
  stat.add("time_jumps_back", n_jumps_);
  stat.add("gaps", n_gaps_);
  stat.add("stale_inputs_held", n_stale_);
  stat.add("late_inputs_dropped", n_late_inputs_);
  stat.add("aux_length_mismatch_dropped", n_aux_mismatch_);
  stat.add("premature_flushes", n_premature_flushes_);
  stat.add("pending", static_cast<long>(pending_scalar_.size()) +
                          (comp_ ? static_cast<long>(comp_->pending()) : 0));
  stat.add("scalar_minus_vector_stamp_s",
           std::isfinite(last_vector_t_) ? last_scalar_t_ - last_vector_t_ : NAN);
}

}  // namespace magcomp::rosio
