// magcomp ROS layer: what the two conversion directions share (internal to src/ros).
#pragma once

#include <Eigen/Core>
#include <fstream>
#include <string>

namespace magcomp::rosio::detail {

// Rows a conversion holds at a time: the columns are read and written a block of rows at a
// time, so a long flight is never held whole.
constexpr Eigen::Index kChunkRows = 1 << 16;

inline bool exists(const std::string& path) { return std::ifstream(path).good(); }

}  // namespace magcomp::rosio::detail
