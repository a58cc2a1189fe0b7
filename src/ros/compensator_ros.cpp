// magcomp ROS layer: the compensator: parameters -> aligned inputs -> compensation -> publish.
#include "magcomp/ros/compensator_ros.h"

#include <magcomp/CompensatedField.h>
#include <sys/stat.h>

#include <cmath>
#include <set>

#include "magcomp/core/error.h"
#include "magcomp/core/geo/anomaly.h"
#include "magcomp/core/geo/igrf.h"
#include "magcomp/core/io/time_base.h"
#include "magcomp/ros/diagnostic_counts.h"
#include "magcomp/ros/params.h"

namespace magcomp::rosio {
namespace {

const std::set<std::string> kCompensatorParams =
    with_input_params({"model_path", "output_topic", "frame_id", "watch_model", "marker_stride",
                       "expected_rate_hz", "flush_after_s", "publish_track_tf", "publish_columns"});

constexpr double kCompensatorTimerPeriod_s = 0.25;  // model-file watch, held inputs, end of stream
constexpr double kCompensatorDiagnosticsPeriod_s = 1.0;
constexpr int kCompensatorOutputQueue = 10000;  // deep: a fast replay's bursts are never dropped
constexpr long kTrackTfEvery = 5;               // outputs between two poses of the aircraft
constexpr size_t kMinHistory = 256;             // samples re-fed to a swapped-in model (at least)

double file_mtime(const std::string& path) {
  struct stat st {};
  if (::stat(path.c_str(), &st) != 0) return 0.0;
  return static_cast<double>(st.st_mtim.tv_sec) + 1e-9 * static_cast<double>(st.st_mtim.tv_nsec);
}

}  // namespace

CompensatorRos::CompensatorRos(ros::NodeHandle nh, ros::NodeHandle pnh)
    : nh_(nh), pnh_(pnh), updater_(nh, pnh) {
  warn_unknown_params(pnh_, kCompensatorParams);  // typos are not silently ignored
  pnh_.param<std::string>("model_path", model_path_, "");
  if (model_path_.empty()) {
    reject_param("model_path", "required (a fitted model YAML written by magcomp calibrate)");
  }
  try {  // the main field for the anomaly output, loaded once (MAGCOMP_IGRF_FILE overrides it)
    igrf_ = std::make_unique<const Igrf>(Igrf::installed());
  } catch (const std::exception& e) {
    ROS_ERROR("magcomp: %s: the anomaly output will be NaN", e.what());
  }
  pnh_.param("watch_model", watch_model_, true);
  pnh_.param("flush_after_s", flush_after_s_, 1.0);
  if (!(flush_after_s_ >= 0)) {
    reject_param("flush_after_s", "must be >= 0 s (0: only on the end-of-stream topic)");
  }
  int stride = 10;
  pnh_.param("marker_stride", stride, 10);
  if (stride < 1) reject_param("marker_stride", "must be >= 1 (outputs per track point)");
  pnh_.param<std::string>("frame_id", frame_id_, "magcomp_track");
  pnh_.param("publish_track_tf", publish_track_tf_, false);
  pnh_.param("publish_columns", publish_columns_, false);
  double rate = 10.0;
  pnh_.param("expected_rate_hz", rate, 10.0);
  require_positive(rate, "expected_rate_hz");
  min_freq_ = 0.5 * rate;
  max_freq_ = 2.0 * rate;

  if (!load_model("start-up")) ROS_ERROR("%s", model_error_.c_str());
  const std::string scalar = comp_ ? comp_->model().scalar : "mag_5_uc";
  const std::string vector = comp_ ? comp_->model().vector : "flux_c";
  const InputParams in = read_input_params(pnh_, scalar, vector);
  base_frame_ = in.base_frame;
  std::string out_topic;
  pnh_.param<std::string>("output_topic", out_topic, "magcomp/compensated");

  pub_out_ = nh_.advertise<magcomp::CompensatedField>(out_topic, kCompensatorOutputQueue);
  pub_marker_ = nh_.advertise<visualization_msgs::MarkerArray>(out_topic + "/track", 2, true);
  if (publish_columns_)
    pub_columns_ =
        nh_.advertise<magcomp::AuxChannels>(out_topic + "/columns", kCompensatorOutputQueue);
  track_ = std::make_unique<TrackMarker>(frame_id_, stride);
  if (publish_track_tf_) tf_broadcaster_ = std::make_unique<tf2_ros::TransformBroadcaster>();
  InputStream::Callbacks cb;
  cb.changed = [this] { process(false); };
  cb.jumped_back = [this] {  // e.g. a bag played in a loop: start again
    restart("time jumped back");
    last_published_t_ = -1e300;
    track_->clear();
  };
  cb.ended = [this](double t) {
    ROS_INFO("magcomp: end of stream at data time %.3f s", t);
    ending_ = true;
    process(false);
  };
  input_ = std::make_unique<InputStream>(nh_, in.topics, in.aligner,
                                         static_cast<uint32_t>(in.queue_size), in.tcp_nodelay,
                                         base_frame_, cb);
  if (comp_) {
    input_->aligner().select_channels(comp_->required_channels());
    input_->aligner().wait_for(!comp_->required_channels().empty(), comp_->needs_igrf());
  }
  srv_reload_ = pnh_.advertiseService("reload", &CompensatorRos::on_reload, this);
  // Wall timers: the model file and the end of a replay happen in wall time, not data time.
  timer_ = nh_.createWallTimer(ros::WallDuration(kCompensatorTimerPeriod_s),
                               [this](const ros::WallTimerEvent&) { on_timer(); });
  updater_.setHardwareID("magcomp compensator: " + scalar + " with " + vector);
  updater_.add("compensator", this, &CompensatorRos::diagnose);
  freq_ = std::make_unique<diagnostic_updater::FrequencyStatus>(
      diagnostic_updater::FrequencyStatusParam(&min_freq_, &max_freq_, 0.1, 10));
  updater_.add(*freq_);
  diag_timer_ =
      nh_.createWallTimer(ros::WallDuration(kCompensatorDiagnosticsPeriod_s),
                          [this](const ros::WallTimerEvent&) { updater_.force_update(); });
  ROS_INFO("magcomp compensator: %s -> %s (model %s)", in.topics.scalar.c_str(), out_topic.c_str(),
           model_path_.c_str());
}

bool CompensatorRos::load_model(const std::string& why) {
  try {
    auto next = std::make_unique<StreamingCompensator>(load_model_yaml(model_path_));
    const double mtime = file_mtime(model_path_);
    if (comp_) {
      if (next->model().scalar != comp_->model().scalar ||
          next->model().vector != comp_->model().vector) {
        model_error_ =
            model_path_ + ": the new model's sensors differ from the subscribed ones; not swapped";
        return false;
      }
      // Swap without losing a sample: the new model re-reads the recent samples (with its own
      // channels) and takes over at the first stamp not yet published. Samples its inputs do not
      // cover yet (the old model did not wait for its channels or the fix) are re-read once
      // they are, before any later sample.
      swap_backlog_.clear();
      for (const StreamSample& s : history_) {
        if (swap_backlog_.empty() && inputs_cover(*next, s.t_s))
          refeed(*next, s);
        else
          swap_backlog_.push_back(s);
      }
      ++n_reloads_;
      ROS_INFO("magcomp: model reloaded (%s): terms now %zu, takes effect after t = %.3f",
               why.c_str(), next->model().terms.size(), last_published_t_);
    }
    comp_ = std::move(next);
    column_names_ = comp_->model().make_column_names();
    if (input_) {
      input_->aligner().select_channels(comp_->required_channels());
      input_->aligner().wait_for(!comp_->required_channels().empty(), comp_->needs_igrf());
    }
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

void CompensatorRos::on_timer() {
  if (watch_model_) {
    const double m = file_mtime(model_path_);
    if (m != 0.0 && m != model_mtime_ && !load_model("file changed")) {
      ROS_ERROR("magcomp: %s", model_error_.c_str());
    }
  }
  drain_swap_backlog(false);
  process(false);  // inputs that never came: hold the latest once max_wait_s has passed
  // No scalar for flush_after_s of wall time (sensor stopped, bag finished without an end
  // message): emit what is pending. Remembered: if the stream goes on, those were premature.
  const bool silent = flush_after_s_ > 0 &&
                      ros::WallTime::now().toSec() - input_->last_scalar_wall_s() > flush_after_s_;
  if (silent && (input_->aligner().pending() > 0 || (comp_ && comp_->pending() > 0))) {
    flushed_at_t_ = input_->aligner().last_scalar_t();
    process(true);
    flush_compensator();
  }
}

void CompensatorRos::process(bool force) {
  StreamAligner& al = input_->aligner();
  if (!comp_) {  // no model: nothing to compute, but the inputs must not pile up
    al.process(ros::WallTime::now().toSec(), true, true, [](const AlignedSample&) {});
    return;
  }
  al.process(ros::WallTime::now().toSec(), ending_, force,
             [this](const AlignedSample& a) { feed(a); });
  if (ending_ && al.pending() == 0) {  // the end message came and every sample is out
    ending_ = false;
    flush_compensator();
  }
}

void CompensatorRos::restart(const char* why) {
  flush_compensator();
  if (comp_) comp_->reset();
  ROS_WARN("magcomp: %s: compensator restarted", why);
}

bool CompensatorRos::inputs_cover(const StreamingCompensator& c, double t_s) const {
  const StreamAligner& al = input_->aligner();
  return (c.required_channels().empty() || al.last_aux_t() >= t_s) &&
         (!c.needs_igrf() || al.last_fix_t() >= t_s);
}

void CompensatorRos::refeed(StreamingCompensator& c, StreamSample s) {
  s.channels.clear();
  for (const auto& name : c.required_channels())
    s.channels.push_back(input_->aligner().channel_at(s.t_s, name));
  if (c.needs_igrf()) s.igrf_nT = igrf_at(s.t_s);
  for (const auto& o : c.push(s)) {
    if (o.t_s > last_published_t_) publish(o);
  }
}

void CompensatorRos::drain_swap_backlog(bool force) {
  while (comp_ && !swap_backlog_.empty() &&
         (force || inputs_cover(*comp_, swap_backlog_.front().t_s))) {
    const StreamSample s = swap_backlog_.front();
    swap_backlog_.pop_front();
    refeed(*comp_, s);
  }
}

void CompensatorRos::flush_compensator() {
  if (!comp_) return;
  drain_swap_backlog(true);
  for (const auto& o : comp_->flush()) publish(o);
  history_.clear();
}

void CompensatorRos::feed(const AlignedSample& a) {
  if (std::isfinite(flushed_at_t_)) {  // a wall-time flush, and the stream went on
    if (a.t_s > flushed_at_t_ && !a.starts_stream) {
      ++n_premature_flushes_;
      ROS_WARN(
          "magcomp: the input stalled for more than flush_after_s (%.2f s of wall time) and "
          "then went on at data time %.3f s: the samples before it were flushed without "
          "their successors (premature_flushes)",
          flush_after_s_, a.t_s);
    }
    flushed_at_t_ = NAN;
  }
  if (a.starts_stream && !history_.empty()) restart("gap in the scalar stamps");
  drain_swap_backlog(true);  // the samples before it first, in time order
  StreamSample s;
  s.t_s = a.t_s;
  s.scalar_nT = a.scalar_nT;
  s.vector_nT = a.vector_nT;
  s.channels = a.channels;
  if (comp_->needs_igrf()) s.igrf_nT = igrf_at(a.t_s);
  history_.push_back(s);
  // Enough recent samples for a swapped-in model to fill its look-ahead and a neural window.
  const size_t keep = std::max<size_t>(4 * std::max(comp_->lookahead(), 3) + 4, kMinHistory);
  while (history_.size() > keep) history_.pop_front();
  for (const auto& o : comp_->push(s)) publish(o);
}

double CompensatorRos::igrf_at(double t) {
  Eigen::Vector3d fix;
  if (!input_->aligner().fix_at(t, &fix)) return NAN;
  try {
    const ros::Time st = input_->stamp(t);
    if (!igrf_) return NAN;
    return igrf_->geodetic(fix.x(), fix.y(), fix.z(), decimal_year_of(st.sec, st.nsec)).total_nT();
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
  msg.header.stamp = input_->stamp(o.t_s);
  msg.header.frame_id = comp_->model().scalar.substr(0, 5);
  msg.measured_nT = o.measured_nT;
  msg.aircraft_correction_nT = o.correction_nT;
  msg.compensated_nT = o.compensated_nT;
  msg.variance_nT2 = o.variance_nT2;
  // A neural stage already needed IGRF at this sample's input; otherwise compute it here.
  const double igrf = std::isfinite(o.igrf_nT) ? o.igrf_nT : igrf_at(o.t_s);
  const double d = input_->aligner().channel_at(o.t_s, "diurnal");  // NaN: none received
  msg.anomaly_nT = anomaly_nT(o.compensated_nT, igrf, std::isfinite(d) ? d : 0.0);
  msg.reference_nT = NAN;
  msg.error_nT = NAN;
  double ref = NAN;
  if (input_->aligner().reference_at(o.t_s, &ref)) {
    msg.reference_nT = ref;
    msg.error_nT = msg.compensated_nT - ref;
  }
  if (publish_columns_ && o.columns.size() > 0) {
    // The model's columns at this sample, before the field: a navigator learning the
    // coefficients online takes them by stamp.
    const auto cols = boost::make_shared<magcomp::AuxChannels>();
    cols->header = msg.header;
    cols->names = column_names_;
    cols->values.assign(o.columns.data(), o.columns.data() + o.columns.size());
    pub_columns_.publish(boost::shared_ptr<const magcomp::AuxChannels>(cols));
  }
  pub_out_.publish(boost::shared_ptr<const magcomp::CompensatedField>(out));
  ++n_out_;
  freq_->tick();
  // rviz: the track in a local east-north-up frame, coloured by the error (or the anomaly).
  Eigen::Vector3d fix;
  if (input_->aligner().fix_at(o.t_s, &fix)) {
    const bool due = track_->add(fix.x(), fix.y(), fix.z(),
                                 std::isfinite(msg.error_nT) ? msg.error_nT : msg.anomaly_nT);
    if (tf_broadcaster_ && n_out_ % kTrackTfEvery == 0) {
      tf_broadcaster_->sendTransform(track_->pose(msg.header.stamp, base_frame_));
    }
    if (due && pub_marker_.getNumSubscribers() > 0) {
      pub_marker_.publish(track_->markers(msg.header.stamp));
    }
  }
}

void CompensatorRos::diagnose(diagnostic_updater::DiagnosticStatusWrapper& stat) {
  const AlignerCounts& c = input_->aligner().counts();
  stat.add("model_path", model_path_);
  stat.add("model_error", model_error_);
  if (comp_) {
    std::string terms;
    for (const auto& t : comp_->model().terms) terms += (terms.empty() ? "" : " ") + t.text();
    stat.add("terms", terms);
    stat.add("lookahead_samples", comp_->lookahead());
    // Terms of a learned law (hinges fitted by diagnose --apply): a shape, not a physical law.
    stat.add("black_box_terms", comp_->model().black_box_terms.size());
    const auto& nn = comp_->model().neural;
    stat.add("neural_stage", nn && nn->trained()
                                 ? std::string(architecture_name(nn->architecture)) + " (" +
                                       mode_name(nn->mode) + ", window " +
                                       std::to_string(nn->window) + ")"
                                 : std::string("none"));
  }
  stat.add("model_reloads", n_reloads_);
  stat.add("fluxgate_frame",
           input_->vector_frame().empty() ? std::string("(as given)") : input_->vector_frame());
  const long faults =
      add_counts(stat, {{"fluxgate_vectors_without_tf", input_->vectors_without_tf()},
                        {"callback_errors", input_->callback_errors()},
                        {"scalar_in", c.scalar_in},
                        {"published", n_out_},
                        {"nan_scalar", c.nan_scalar, true},
                        {"duplicate_stamps", c.duplicate_stamps, true},
                        {"out_of_order_dropped", c.out_of_order, true},
                        {"time_jumps_back", c.jumps_back, true},
                        {"gaps", c.gaps, true},
                        {"stale_inputs_held", c.stale_inputs_held, true},
                        {"late_inputs_dropped", c.late_inputs, true},
                        {"aux_length_mismatch_dropped", c.aux_mismatch, true},
                        {"premature_flushes", n_premature_flushes_, true}});
  stat.add("pending", static_cast<long>(input_->aligner().pending()) +
                          (comp_ ? static_cast<long>(comp_->pending()) : 0));
  const double lv = input_->aligner().last_vector_t();
  stat.add("scalar_minus_vector_stamp_s",
           std::isfinite(lv) ? input_->aligner().last_scalar_t() - lv : NAN);
  if (!comp_) {
    stat.summary(diagnostic_msgs::DiagnosticStatus::ERROR, "no model: " + model_error_);
  } else if (faults > 0) {
    stat.summary(diagnostic_msgs::DiagnosticStatus::WARN,
                 "running; input faults seen (see counts)");
  } else {
    stat.summary(diagnostic_msgs::DiagnosticStatus::OK, "running");
  }
}

}  // namespace magcomp::rosio
