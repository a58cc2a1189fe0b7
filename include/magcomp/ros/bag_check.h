// magcomp ROS layer: check a bag file's structure before the rosbag library reads it.
#pragma once

#include <cstdint>
#include <string>

namespace magcomp::rosio {

/// Messages of some connections, handed over in file order while a bag is checked (a reader
/// that needs no index in memory: the pages of each chunk are let go once it is read).
class BagVisitor {
 public:
  virtual ~BagVisitor() = default;
  /// Whether the messages of a connection (topic, message type) are wanted.
  virtual bool wants(const std::string& topic, const std::string& type) = 0;
  /// The number of messages on a wanted topic the bag's index lists, before the first message.
  virtual void counted(const std::string& /*topic*/, uint64_t /*messages*/) {}
  /// One wanted message: its topic and its serialised bytes (valid during the call).
  virtual void message(const std::string& topic, const uint8_t* data, uint64_t size) = 0;
};

/// Walks a bag file (format 2.0) record by record: the version line, the bag header, the index
/// (connections and chunk infos), every chunk and its index records, and the records inside
/// uncompressed chunks, checking every length and offset against the file. rosbag asserts (and
/// aborts the process) on some corrupt bags; after this check it does not meet them. With a
/// visitor, the wanted messages of uncompressed chunks are handed to it in file order; returns
/// false when the bag holds compressed chunks (whose messages are not handed over). Memory stays
/// at one chunk whatever the bag's size. Throws magcomp::Error naming the file, what is wrong and
/// the byte offset.
bool check_bag_structure(const std::string& path, BagVisitor* visitor = nullptr);

}  // namespace magcomp::rosio
