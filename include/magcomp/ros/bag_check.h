// magcomp ROS layer: check a bag file's structure before the rosbag library reads it.
#pragma once

#include <string>

namespace magcomp::rosio {

/// Walks a bag file (format 2.0) record by record: the version line, the bag header, the index
/// (connections and chunk infos), every chunk and its index records, and the records inside
/// uncompressed chunks, checking every length and offset against the file. rosbag asserts (and
/// aborts the process) on some corrupt bags; after this check it does not meet them. Throws
/// magcomp::Error naming the file, what is wrong and the byte offset.
void check_bag_structure(const std::string& path);

}  // namespace magcomp::rosio
