// magcomp ROS layer: what every message callback of a node runs inside. A node survives any input:
// an exception from a callback is logged (throttled), counted for the diagnostics and the message
// dropped; it never ends the node, and a nodelet never takes its manager down.
#pragma once

#include <ros/console.h>
#include <ros/time.h>

#include <cstdint>
#include <exception>

namespace magcomp::rosio {

/// Runs `body`; an exception it throws is logged as "WHO: what (input dropped)" at most every
/// 5 s and counted in *errors.
template <class Body>
void guarded(const char* who, long* errors, Body&& body) {
  try {
    body();
  } catch (const std::exception& e) {
    ++*errors;
    ROS_ERROR_THROTTLE(5.0, "%s: %s (input dropped)", who, e.what());
  }
}

/// Whether a header stamp can serve as data time: its seconds below 2^32 - 1, so that the stamp,
/// turned into seconds and back (ros::Time(double)), stays inside ROS time's range.
inline bool usable_stamp(const ros::Time& t) { return t.sec < UINT32_MAX; }

}  // namespace magcomp::rosio
