// magcomp: the inputs of a stream aligned to each scalar stamp (ROS-free; the nodes feed it).
//
// A scalar magnetometer stamps the samples; the fluxgate, the auxiliary channels, the fix and a
// reference arrive on their own, at their own times and in their own order. For every scalar
// stamp the aligner interpolates each input to that stamp (nothing is dropped for falling
// between two stamps), waits for inputs that have not yet covered it, and counts every fault:
// NaN, duplicate, out-of-order and jumping stamps, gaps, late and held inputs.
#pragma once

#include <Eigen/Core>
#include <deque>
#include <functional>
#include <string>
#include <vector>

namespace magcomp {

/// Settings, in seconds of data time unless said otherwise.
struct AlignerSettings {
  double max_wait_s = 0.5;   ///< a sample waits this long (data AND wall time) for its inputs
  double max_gap_s = 1.0;    ///< a larger gap between scalar stamps starts a new stream
  double jump_back_s = 1.0;  ///< a stamp this far back resets everything (a bag loop)
  double buffer_s = 10.0;    ///< input history kept for interpolation
};

/// What the aligner saw (all counts since construction).
struct AlignerCounts {
  long scalar_in = 0;          ///< scalar messages received
  long nan_scalar = 0;         ///< ... holding a NaN, Inf or |value| > 1e6 nT (taken as NaN)
  long duplicate_stamps = 0;   ///< a scalar stamp equal to the last one (dropped)
  long out_of_order = 0;       ///< a scalar stamp slightly before the last one (dropped)
  long jumps_back = 0;         ///< a jump back over jump_back_s (everything reset)
  long gaps = 0;               ///< a gap over max_gap_s between emitted samples
  long stale_inputs_held = 0;  ///< samples emitted with an input held or missing
  long late_inputs = 0;        ///< inputs whose stamp was not after their topic's last (dropped)
  long aux_mismatch = 0;       ///< aux messages whose names and values differ in length (dropped)
};

/// One scalar sample with its inputs at its stamp.
struct AlignedSample {
  double t_s = 0.0;  ///< data time, s
  double scalar_nT = 0.0;
  Eigen::Vector3d vector_nT;     ///< interpolated (or held, or NaN when none came)
  std::vector<double> channels;  ///< the selected channels (NaN when absent)
  bool stale = false;            ///< an input was held or missing
  bool starts_stream = false;    ///< the first sample after a gap (or the very first)
};

class StreamAligner {
 public:
  explicit StreamAligner(AlignerSettings settings = {});

  /// The aux channels each sample carries, by name, in this order.
  void select_channels(const std::vector<std::string>& names);
  /// Whether a sample waits for the aux message and the fix of its stamp before it is emitted.
  void wait_for(bool aux, bool fix) {
    wait_aux_ = aux;
    wait_fix_ = fix;
  }

  enum class ScalarResult { kAccepted, kDuplicate, kOutOfOrder, kJumpedBack };
  /// A scalar sample at data time t_s (s), received at wall time wall_s (s). kJumpedBack: every
  /// input buffer was cleared first and the caller should reset what it holds.
  ScalarResult add_scalar(double t_s, double value_nT, double wall_s);
  /// The vector sensor in nT (already in the model's frame). False: late, dropped (counted).
  bool add_vector(double t_s, const Eigen::Vector3d& field_nT);
  /// An aux message: names and values of the same length (else dropped and counted).
  bool add_aux(double t_s, const std::vector<std::string>& names,
               const std::vector<double>& values);
  /// The fix: latitude (deg), longitude (deg), height (m).
  bool add_fix(double t_s, const Eigen::Vector3d& lat_lon_height);
  /// A reference magnetometer, nT.
  bool add_reference(double t_s, double value_nT);

  /// Emits, in time order, every pending sample whose inputs cover its stamp, or that has waited
  /// max_wait_s in data time (a later scalar is that far ahead) and in wall time; with `ending`
  /// (no later scalar will come) the wall time alone decides; with `force` all of them.
  void process(double wall_s, bool ending, bool force,
               const std::function<void(const AlignedSample&)>& sink);

  /// Inputs at t (interpolated; false outside what is buffered).
  bool reference_at(double t_s, double* value_nT) const;
  bool fix_at(double t_s, Eigen::Vector3d* lat_lon_height) const;
  /// A channel of the aux messages at t by name (NaN when absent or not covered).
  double channel_at(double t_s, const std::string& name) const;

  size_t pending() const { return pending_.size(); }
  double last_scalar_t() const { return last_scalar_t_; }
  double last_vector_t() const { return vectors_.empty() ? NAN : vectors_.back().t; }
  /// Data time (s) of the latest aux message and fix (NaN before the first).
  double last_aux_t() const { return aux_.empty() ? NAN : aux_.back().t; }
  double last_fix_t() const { return fixes_.empty() ? NAN : fixes_.back().t; }
  const AlignerCounts& counts() const { return counts_; }
  /// Forgets every buffered input and pending sample (the counts stay).
  void clear();

 private:
  template <typename T>
  struct Timed {
    double t;
    T v;
  };
  template <typename T>
  bool append(std::deque<Timed<T>>& buf, double t, T v);
  template <typename T>
  static bool interpolate(const std::deque<Timed<T>>& buf, double t, T* out);
  std::vector<double> channels_at(double t, const std::vector<int>& index, bool* covered) const;
  void reindex();

  struct Pending {
    double t, value_nT, wall_s;
  };
  AlignerSettings s_;
  bool wait_aux_ = false, wait_fix_ = false;
  std::vector<std::string> selected_;   // channel names each sample carries
  std::vector<std::string> aux_names_;  // names in the aux messages
  std::vector<int> selected_index_;     // selected_[k] -> index in aux_names_ (-1: absent)
  std::deque<Pending> pending_;
  std::deque<Timed<Eigen::Vector3d>> vectors_, fixes_;
  std::deque<Timed<std::vector<double>>> aux_;
  std::deque<Timed<double>> references_;
  double last_scalar_t_ = -1e300, last_emitted_t_ = -1e300;
  AlignerCounts counts_;
};

}  // namespace magcomp
