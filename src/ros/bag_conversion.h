// magcomp ROS layer: what the two conversion directions share (internal to src/ros).
#pragma once

#include <sys/stat.h>

#include <Eigen/Core>
#include <string>

namespace magcomp::rosio::detail {

// Rows a conversion holds at a time: the columns are read and written a block of rows at a
// time, so a long flight is never held whole.
constexpr Eigen::Index kChunkRows = 1 << 16;

/// Whether a path exists (stat: never opens it, so a pipe cannot block the caller).
inline bool exists(const std::string& path) {
  struct stat st {};
  return ::stat(path.c_str(), &st) == 0;
}

}  // namespace magcomp::rosio::detail
