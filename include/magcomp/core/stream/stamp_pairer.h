// magcomp: the two halves of one sample, sent on two topics with the same stamp (an INS's fix
// and its attitude; the compensator's anomaly and its model's columns), paired by exact stamp
// (ROS-free; the navigator feeds it). Unlike the StreamAligner, nothing is interpolated: both
// halves describe one instant, so a half pairs only with the other half of its own stamp.
#pragma once

#include <cstddef>
#include <map>
#include <optional>
#include <utility>

namespace magcomp {

/// Settings, in seconds of data time.
struct PairerSettings {
  double max_age_s = 10.0;  ///< a half older than the newest stamp by this never pairs: dropped
  size_t max_held = 20000;  ///< halves held on one side, at most (the oldest are dropped)
  bool drop_older = true;   ///< a pair at t drops the halves before t (in-order topics)
};

/// What the pairer did, since construction.
struct PairerCounts {
  long paired = 0;          ///< pairs made
  long first_dropped = 0;   ///< first halves dropped without their second
  long second_dropped = 0;  ///< second halves dropped without their first
};

template <class First, class Second>
class StampPairer {
 public:
  /// A sample whose two halves came: its stamp (s) and both halves.
  struct Pair {
    double t_s;
    First first;
    Second second;
  };

  explicit StampPairer(PairerSettings settings = {}) : s_(settings) {}

  /// The first half of the sample at t_s (s); the pair when its second half is already in. A
  /// half of a stamp already waiting replaces it.
  std::optional<Pair> add_first(double t_s, First v) {
    first_[t_s] = std::move(v);
    return match(t_s);
  }
  /// The second half of the sample at t_s (s); the pair when its first half is already in.
  std::optional<Pair> add_second(double t_s, Second v) {
    second_[t_s] = std::move(v);
    return match(t_s);
  }
  /// Halves waiting for their other half (both sides).
  size_t waiting() const { return first_.size() + second_.size(); }
  const PairerCounts& counts() const { return counts_; }
  /// Forgets every waiting half (a restart), without counting them as dropped.
  void clear() {
    first_.clear();
    second_.clear();
  }

 private:
  std::optional<Pair> match(double t_s) {
    auto f = first_.find(t_s);
    auto g = second_.find(t_s);
    if (f == first_.end() || g == second_.end()) {
      drop_before(t_s - s_.max_age_s);
      return std::nullopt;
    }
    Pair p{t_s, std::move(f->second), std::move(g->second)};
    first_.erase(f);
    second_.erase(g);
    ++counts_.paired;
    if (s_.drop_older) drop_before(t_s);
    return p;
  }

  void drop_before(double t_s) {
    counts_.first_dropped += drop(&first_, t_s);
    counts_.second_dropped += drop(&second_, t_s);
  }

  template <class M>
  long drop(M* m, double t_s) const {
    long n = 0;
    while (!m->empty() && (m->begin()->first < t_s || m->size() > s_.max_held))
      m->erase(m->begin()), ++n;
    return n;
  }

  PairerSettings s_;
  std::map<double, First> first_;
  std::map<double, Second> second_;
  PairerCounts counts_;
};

}  // namespace magcomp
