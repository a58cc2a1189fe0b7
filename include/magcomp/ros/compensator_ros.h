// magcomp ROS layer: the compensator (one class; the node and the nodelet construct it).
#pragma once

#include <diagnostic_updater/diagnostic_updater.h>
#include <diagnostic_updater/publisher.h>
#include <ros/ros.h>
#include <std_srvs/Trigger.h>
#include <tf2_ros/transform_broadcaster.h>

#include <deque>
#include <memory>
#include <string>

#include "magcomp/core/geo/igrf.h"
#include "magcomp/core/stream/streaming_compensator.h"
#include "magcomp/ros/input_stream.h"
#include "magcomp/ros/track_marker.h"

namespace magcomp::rosio {

/// Parameters -> inputs aligned to each scalar stamp (InputStream, the core's StreamAligner) ->
/// the fitted model applied sample by sample (the core's StreamingCompensator, the offline code)
/// -> magcomp/CompensatedField, the rviz track, diagnostics. Stamps come from the data. Reloads
/// its model on ~reload or when the file changes, without losing a sample. Parameters:
/// config/compensator.yaml.
class CompensatorRos {
 public:
  /// Reads and validates the private parameters (throws magcomp::Error naming the parameter).
  CompensatorRos(ros::NodeHandle nh, ros::NodeHandle pnh);

 private:
  bool load_model(const std::string& why);
  bool on_reload(std_srvs::Trigger::Request&, std_srvs::Trigger::Response& res);
  void on_timer();
  /// Lets out what the aligner holds ready (force: everything) and compensates it.
  void process(bool force);
  void feed(const AlignedSample& a);
  void publish(const StreamOutput& o);
  /// Emits the compensator's look-ahead: the end of a stream.
  void flush_compensator();
  void restart(const char* why);
  /// Whether the buffered inputs cover data time t_s (s) for `c`'s channels and IGRF.
  bool inputs_cover(const StreamingCompensator& c, double t_s) const;
  /// Fills `s`'s channels and IGRF for `c` from the buffered inputs, feeds it, and publishes
  /// what comes out after the last published stamp.
  void refeed(StreamingCompensator& c, StreamSample s);
  /// Feeds the swapped-in model the samples its inputs did not cover at the swap: those now
  /// covered (all of them with `force`, held inputs as the aligner holds them).
  void drain_swap_backlog(bool force);
  /// IGRF total field (nT) at data time t from the interpolated fix; NaN without a fix.
  double igrf_at(double t);
  void diagnose(diagnostic_updater::DiagnosticStatusWrapper& stat);

  ros::NodeHandle nh_, pnh_;
  // Parameters (SI units, validated at start-up).
  std::string model_path_, frame_id_, base_frame_;
  double flush_after_s_ = 1.0;
  bool watch_model_ = true, publish_track_tf_ = false;
  // The pipeline.
  std::unique_ptr<InputStream> input_;
  std::unique_ptr<StreamingCompensator> comp_;
  std::unique_ptr<const Igrf> igrf_;  ///< the main field, loaded at start-up (anomaly output)
  std::deque<StreamSample> history_;  // recent samples, re-fed to a swapped-in model
  // Samples a swapped-in model re-reads once its inputs cover them: a model swap may come while
  // the aux messages or the fix lag the scalar, which the old model did not wait for.
  std::deque<StreamSample> swap_backlog_;
  std::string model_error_;
  double model_mtime_ = 0.0;
  double last_published_t_ = -1e300;
  bool ending_ = false;        // end-of-stream received, pending samples still going out
  double flushed_at_t_ = NAN;  // data time of the last wall-time flush (NaN: none)
  // Counters for diagnostics (the aligner counts the input faults).
  long n_out_ = 0, n_reloads_ = 0, n_premature_flushes_ = 0;
  // Outputs.
  ros::Publisher pub_out_, pub_marker_, pub_columns_;
  bool publish_columns_ = false;           // <output_topic>/columns: the model's columns per sample
  std::vector<std::string> column_names_;  // of the model in use
  ros::ServiceServer srv_reload_;
  ros::WallTimer timer_, diag_timer_;
  diagnostic_updater::Updater updater_;
  double min_freq_ = 5.0, max_freq_ = 50.0;
  std::unique_ptr<diagnostic_updater::FrequencyStatus> freq_;
  std::unique_ptr<TrackMarker> track_;
  std::unique_ptr<tf2_ros::TransformBroadcaster> tf_broadcaster_;
};

}  // namespace magcomp::rosio
