// magcomp ROS layer: samples the navigator holds by time (INS halves, reference fixes,
// orientations), pruned behind the filter and bounded in number.
#pragma once

#include <cstddef>

namespace magcomp::rosio {

constexpr size_t kMaxHeld = 20000;  // samples held in one map, at most

/// Drops the entries of a time-keyed map (s) before t, then the oldest beyond kMaxHeld.
template <class M>
void prune_before(M& m, double t) {
  while (!m.empty() && m.begin()->first < t) m.erase(m.begin());
  while (m.size() > kMaxHeld) m.erase(m.begin());
}

}  // namespace magcomp::rosio
