// magcomp ROS layer: a streaming writer of ROS bag format 2.0 files (uncompressed, indexed),
// for the converter's millions of small messages. rosbag::Bag::write builds a std::map header,
// two std::multiset index entries and several stdio calls per message; this writer appends
// each record to an in-memory chunk and keeps plain index vectors, so the file is the same format
// rosbag, rosbag play and rosbag::View read, at a fraction of the cost per message.
#pragma once

#include <ros/message_traits.h>
#include <ros/serialization.h>
#include <ros/time.h>

#include <cstdint>
#include <cstdio>
#include <map>
#include <string>
#include <vector>

namespace magcomp::rosio {

class BagWriter {
 public:
  /// Opens `path` for writing (truncates). Throws magcomp::Error naming the file.
  explicit BagWriter(const std::string& path, size_t chunk_bytes = 4 * 1024 * 1024);
  ~BagWriter();
  BagWriter(const BagWriter&) = delete;
  BagWriter& operator=(const BagWriter&) = delete;

  /// A topic's connection id (registers the topic with message type M on first use).
  template <typename M>
  uint32_t connection(const std::string& topic) {
    auto it = topic_ids_.find(topic);
    if (it != topic_ids_.end()) return it->second;
    Connection c;
    c.topic = topic;
    c.type = ros::message_traits::datatype<M>();
    c.md5sum = ros::message_traits::md5sum<M>();
    c.definition = ros::message_traits::definition<M>();
    return add_connection(std::move(c));
  }

  /// Appends one message on a connection, stamped `t`.
  template <typename M>
  void write(uint32_t conn, const ros::Time& t, const M& msg) {
    const uint32_t len = ros::serialization::serializationLength(msg);
    uint8_t* data = begin_message(conn, t, len);
    ros::serialization::OStream s(data, len);
    ros::serialization::serialize(s, msg);
  }

  /// Writes the last chunk, the index and the file header. Throws magcomp::Error on failure.
  void close();

 private:
  struct Connection {
    std::string topic, type, md5sum, definition;
  };
  struct IndexEntry {
    uint32_t sec, nsec, offset;
  };
  struct ChunkInfo {
    uint64_t pos;
    ros::Time start, end;
    std::vector<std::pair<uint32_t, uint32_t>> counts;  // connection, messages
  };

  uint32_t add_connection(Connection c);
  uint8_t* begin_message(uint32_t conn, const ros::Time& t, uint32_t len);
  void flush_chunk();
  void put(const void* p, size_t n);
  std::vector<uint8_t> connection_record(uint32_t id) const;
  void write_file_header(uint64_t index_pos);

  std::string path_;
  std::FILE* file_ = nullptr;
  size_t chunk_bytes_;
  std::map<std::string, uint32_t> topic_ids_;
  std::vector<Connection> connections_;
  std::vector<bool> connection_written_;
  std::vector<uint8_t> chunk_;                  // the current chunk's records
  std::vector<std::vector<IndexEntry>> index_;  // per connection, this chunk
  ros::Time chunk_start_, chunk_end_;
  bool chunk_empty_ = true;
  std::vector<ChunkInfo> chunks_;
  uint64_t pos_ = 0;  // bytes written to the file
};

}  // namespace magcomp::rosio
