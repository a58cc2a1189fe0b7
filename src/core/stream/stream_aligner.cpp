// magcomp: aligning a stream's inputs to each scalar stamp.
#include "magcomp/core/stream/stream_aligner.h"

#include <algorithm>
#include <cmath>

#include "magcomp/core/math/constants.h"

namespace magcomp {

StreamAligner::StreamAligner(AlignerSettings settings) : s_(settings) {}

void StreamAligner::select_channels(const std::vector<std::string>& names) {
  selected_ = names;
  reindex();
}

void StreamAligner::reindex() {
  selected_index_.clear();
  for (const auto& n : selected_) {
    auto it = std::find(aux_names_.begin(), aux_names_.end(), n);
    selected_index_.push_back(it == aux_names_.end() ? -1
                                                     : static_cast<int>(it - aux_names_.begin()));
  }
}

void StreamAligner::clear() {
  pending_.clear();
  vectors_.clear();
  fixes_.clear();
  aux_.clear();
  references_.clear();
  last_scalar_t_ = last_emitted_t_ = -1e300;
}

template <typename T>
bool StreamAligner::append(std::deque<Timed<T>>& buf, double t, T v) {
  if (!buf.empty() && t <= buf.back().t) {
    if (buf.back().t - t <= s_.jump_back_s) {
      ++counts_.late_inputs;
      return false;
    }
    buf.clear();  // far back: this input starts again (a bag loop)
  }
  buf.push_back({t, std::move(v)});
  while (buf.size() > 2 && buf.front().t < t - s_.buffer_s) buf.pop_front();
  return true;
}

template <typename T>
bool StreamAligner::interpolate(const std::deque<Timed<T>>& buf, double t, T* out) {
  if (buf.empty() || t > buf.back().t || t < buf.front().t) return false;
  auto hi = std::lower_bound(buf.begin(), buf.end(), t,
                             [](const Timed<T>& a, double x) { return a.t < x; });
  if (hi->t == t) {
    *out = hi->v;
    return true;
  }
  const auto lo = hi - 1;
  const double w = (t - lo->t) / (hi->t - lo->t);
  if constexpr (std::is_same_v<T, std::vector<double>>) {
    *out = lo->v;
    for (size_t k = 0; k < out->size(); ++k) (*out)[k] = (1 - w) * lo->v[k] + w * hi->v[k];
  } else {
    *out = (1 - w) * lo->v + w * hi->v;
  }
  return true;
}

StreamAligner::ScalarResult StreamAligner::add_scalar(double t, double value, double wall_s) {
  ++counts_.scalar_in;
  if (t == last_scalar_t_) {
    ++counts_.duplicate_stamps;
    return ScalarResult::kDuplicate;
  }
  ScalarResult result = ScalarResult::kAccepted;
  if (t < last_scalar_t_) {
    if (last_scalar_t_ - t <= s_.jump_back_s) {
      ++counts_.out_of_order;
      return ScalarResult::kOutOfOrder;
    }
    ++counts_.jumps_back;
    clear();
    result = ScalarResult::kJumpedBack;
  }
  last_scalar_t_ = t;
  if (!(std::abs(value) <= kMaxField_nT)) {  // NaN, Inf, or no magnetometer's reading
    ++counts_.nan_scalar;
    value = NAN;
  }
  pending_.push_back({t, value, wall_s});
  return result;
}

bool StreamAligner::add_vector(double t, const Eigen::Vector3d& v) {
  return append(vectors_, t, Eigen::Vector3d(v));
}

bool StreamAligner::add_aux(double t, const std::vector<std::string>& names,
                            const std::vector<double>& values) {
  if (names.size() != values.size()) {  // which value is which cannot be known
    ++counts_.aux_mismatch;
    return false;
  }
  if (names != aux_names_) {  // a new channel list: re-index (older values are dropped)
    aux_names_ = names;
    aux_.clear();
    reindex();
  }
  return append(aux_, t, std::vector<double>(values));
}

bool StreamAligner::add_fix(double t, const Eigen::Vector3d& llh) {
  return append(fixes_, t, Eigen::Vector3d(llh));
}

bool StreamAligner::add_reference(double t, double v) { return append(references_, t, double(v)); }

std::vector<double> StreamAligner::channels_at(double t, const std::vector<int>& index,
                                               bool* covered) const {
  std::vector<double> out(index.size(), NAN);
  std::vector<double> a;
  *covered = interpolate(aux_, t, &a);
  if (!*covered) {
    if (aux_.empty()) return out;
    a = aux_.back().v;  // held
  }
  for (size_t k = 0; k < index.size(); ++k) {
    if (index[k] >= 0 && static_cast<size_t>(index[k]) < a.size())
      out[k] = a[static_cast<size_t>(index[k])];
  }
  return out;
}

void StreamAligner::process(double wall_s, bool ending, bool force,
                            const std::function<void(const AlignedSample&)>& sink) {
  while (!pending_.empty()) {
    const Pending p = pending_.front();
    const bool covered = !vectors_.empty() && vectors_.back().t >= p.t &&
                         (!wait_aux_ || (!aux_.empty() && aux_.back().t >= p.t)) &&
                         (!wait_fix_ || (!fixes_.empty() && fixes_.back().t >= p.t));
    // Held inputs only after waiting max_wait_s in data time AND in wall time (on a fast replay
    // data time runs ahead of the transport; in real time the two agree). After the end of the
    // stream no later scalar will come: the wall time alone decides.
    const bool waited =
        (ending || last_scalar_t_ - p.t > s_.max_wait_s) && wall_s - p.wall_s > s_.max_wait_s;
    if (!covered && !waited && !force) return;
    pending_.pop_front();
    AlignedSample a;
    a.t_s = p.t;
    a.scalar_nT = p.value_nT;
    if (!interpolate(vectors_, p.t, &a.vector_nT)) {
      a.stale = true;
      if (vectors_.empty()) {
        a.vector_nT.setConstant(NAN);
      } else {
        a.vector_nT = vectors_.back().v;
      }
    }
    bool aux_covered = true;
    a.channels = channels_at(p.t, selected_index_, &aux_covered);
    if (wait_aux_ && !aux_covered) a.stale = true;
    Eigen::Vector3d fix;
    if (wait_fix_ && !interpolate(fixes_, p.t, &fix)) a.stale = true;
    if (a.stale) ++counts_.stale_inputs_held;
    a.starts_stream = last_emitted_t_ < -1e299 || p.t - last_emitted_t_ > s_.max_gap_s;
    if (last_emitted_t_ > -1e299 && p.t - last_emitted_t_ > s_.max_gap_s) ++counts_.gaps;
    last_emitted_t_ = p.t;
    sink(a);
  }
}

bool StreamAligner::reference_at(double t, double* v) const {
  return interpolate(references_, t, v);
}

bool StreamAligner::fix_at(double t, Eigen::Vector3d* llh) const {
  return interpolate(fixes_, t, llh);
}

double StreamAligner::channel_at(double t, const std::string& name) const {
  auto it = std::find(aux_names_.begin(), aux_names_.end(), name);
  if (it == aux_names_.end()) return NAN;
  bool covered = false;
  const auto v = channels_at(t, {static_cast<int>(it - aux_names_.begin())}, &covered);
  return v[0];
}

}  // namespace magcomp
