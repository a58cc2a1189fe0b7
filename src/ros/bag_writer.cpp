// magcomp ROS layer: ROS bag format 2.0 writer (http://wiki.ros.org/Bags/Format/2.0).
#include "magcomp/ros/bag_writer.h"

#include <cstring>

#include "bag_record_ops.h"
#include "magcomp/core/error.h"

namespace magcomp::rosio {
namespace {

constexpr size_t kFileHeaderBytes = 4096;  // the header record is padded to this

template <typename T>
void append_raw(std::vector<uint8_t>& b, T v) {  // little-endian (x86, as rosbag assumes)
  const auto* p = reinterpret_cast<const uint8_t*>(&v);
  b.insert(b.end(), p, p + sizeof(T));
}

/// A header field "name=value" with its 4-byte length.
void field(std::vector<uint8_t>& b, const char* name, const void* value, size_t n) {
  const size_t name_len = std::strlen(name);
  append_raw<uint32_t>(b, static_cast<uint32_t>(name_len + 1 + n));
  b.insert(b.end(), name, name + name_len);
  b.push_back('=');
  const auto* p = static_cast<const uint8_t*>(value);
  b.insert(b.end(), p, p + n);
}
template <typename T>
void field_of(std::vector<uint8_t>& b, const char* name, T v) {
  field(b, name, &v, sizeof(T));
}
void field_str(std::vector<uint8_t>& b, const char* name, const std::string& s) {
  field(b, name, s.data(), s.size());
}
void field_time(std::vector<uint8_t>& b, const char* name, const ros::Time& t) {
  uint32_t v[2] = {t.sec, t.nsec};
  field(b, name, v, sizeof(v));
}

/// A record: header length, header, data length, data.
void record(std::vector<uint8_t>& out, const std::vector<uint8_t>& header,
            const std::vector<uint8_t>& data) {
  append_raw<uint32_t>(out, static_cast<uint32_t>(header.size()));
  out.insert(out.end(), header.begin(), header.end());
  append_raw<uint32_t>(out, static_cast<uint32_t>(data.size()));
  out.insert(out.end(), data.begin(), data.end());
}

}  // namespace

BagWriter::BagWriter(const std::string& path, size_t chunk_bytes)
    : path_(path), chunk_bytes_(chunk_bytes) {
  file_ = std::fopen(path.c_str(), "wb");
  if (!file_) throw Error(path + ": cannot open for writing");
  static const char kMagic[] = "#ROSBAG V2.0\n";
  put(kMagic, sizeof(kMagic) - 1);
  write_file_header(0);  // rewritten by close() with the index position
  chunk_.reserve(chunk_bytes_ + (1 << 16));
}

BagWriter::~BagWriter() {
  if (file_) std::fclose(file_);
}

void BagWriter::put(const void* p, size_t n) {
  if (n && std::fwrite(p, 1, n, file_) != n) throw Error(path_ + ": write failed (disk full?)");
  pos_ += n;
}

void BagWriter::write_file_header(uint64_t index_pos) {
  std::vector<uint8_t> h, out;
  field_of<uint8_t>(h, "op", kOpBagHeader);
  field_of<uint64_t>(h, "index_pos", index_pos);
  field_of<uint32_t>(h, "conn_count", static_cast<uint32_t>(connections_.size()));
  field_of<uint32_t>(h, "chunk_count", static_cast<uint32_t>(chunks_.size()));
  const std::vector<uint8_t> pad(kFileHeaderBytes - h.size() - 8, ' ');
  record(out, h, pad);
  put(out.data(), out.size());
}

uint32_t BagWriter::add_connection(Connection c) {
  const uint32_t id = static_cast<uint32_t>(connections_.size());
  topic_ids_[c.topic] = id;
  connections_.push_back(std::move(c));
  connection_written_.push_back(false);
  index_.emplace_back();
  return id;
}

std::vector<uint8_t> BagWriter::connection_record(uint32_t id) const {
  const Connection& c = connections_[id];
  std::vector<uint8_t> h, d, out;
  field_of<uint8_t>(h, "op", kOpConnection);
  field_of<uint32_t>(h, "conn", id);
  field_str(h, "topic", c.topic);
  field_str(d, "topic", c.topic);
  field_str(d, "type", c.type);
  field_str(d, "md5sum", c.md5sum);
  field_str(d, "message_definition", c.definition);
  field_str(d, "callerid", "/magcomp_convert");
  field_str(d, "latching", "0");
  record(out, h, d);
  return out;
}

uint8_t* BagWriter::begin_message(uint32_t conn, const ros::Time& t, uint32_t len) {
  if (chunk_.size() >= chunk_bytes_) flush_chunk();  // the previous message is serialised by now
  if (!connection_written_[conn]) {  // first use: the connection record goes into the chunk
    const std::vector<uint8_t> r = connection_record(conn);
    chunk_.insert(chunk_.end(), r.begin(), r.end());
    connection_written_[conn] = true;
  }
  if (chunk_empty_ || t < chunk_start_) chunk_start_ = t;
  if (chunk_empty_ || t > chunk_end_) chunk_end_ = t;
  chunk_empty_ = false;
  index_[conn].push_back({t.sec, t.nsec, static_cast<uint32_t>(chunk_.size())});
  // Header: op, conn, time (fixed layout: 3 fields).
  append_raw<uint32_t>(chunk_, 4 + 3 + 1 + 4 + 5 + 4 + 4 + 5 + 8);
  append_raw<uint32_t>(chunk_, 4);
  chunk_.insert(chunk_.end(), {'o', 'p', '=', kOpMessage});
  append_raw<uint32_t>(chunk_, 5 + 4);
  chunk_.insert(chunk_.end(), {'c', 'o', 'n', 'n', '='});
  append_raw<uint32_t>(chunk_, conn);
  append_raw<uint32_t>(chunk_, 5 + 8);
  chunk_.insert(chunk_.end(), {'t', 'i', 'm', 'e', '='});
  append_raw<uint32_t>(chunk_, t.sec);
  append_raw<uint32_t>(chunk_, t.nsec);
  append_raw<uint32_t>(chunk_, len);
  const size_t at = chunk_.size();
  chunk_.resize(at + len);
  return chunk_.data() + at;  // valid until the next message (the caller serialises into it)
}

void BagWriter::flush_chunk() {
  if (chunk_empty_) return;
  ChunkInfo info;
  info.pos = pos_;
  info.start = chunk_start_;
  info.end = chunk_end_;
  std::vector<uint8_t> h, out;
  field_of<uint8_t>(h, "op", kOpChunk);
  field_str(h, "compression", "none");
  field_of<uint32_t>(h, "size", static_cast<uint32_t>(chunk_.size()));
  append_raw<uint32_t>(out, static_cast<uint32_t>(h.size()));
  out.insert(out.end(), h.begin(), h.end());
  append_raw<uint32_t>(out, static_cast<uint32_t>(chunk_.size()));
  put(out.data(), out.size());
  put(chunk_.data(), chunk_.size());
  for (uint32_t c = 0; c < index_.size(); ++c) {
    auto& entries = index_[c];
    if (entries.empty()) continue;
    std::vector<uint8_t> ih, id, rec;
    field_of<uint8_t>(ih, "op", kOpIndex);
    field_of<uint32_t>(ih, "ver", 1);
    field_of<uint32_t>(ih, "conn", c);
    field_of<uint32_t>(ih, "count", static_cast<uint32_t>(entries.size()));
    id.reserve(entries.size() * 12);
    for (const auto& e : entries) {
      append_raw<uint32_t>(id, e.sec);
      append_raw<uint32_t>(id, e.nsec);
      append_raw<uint32_t>(id, e.offset);
    }
    record(rec, ih, id);
    put(rec.data(), rec.size());
    info.counts.emplace_back(c, static_cast<uint32_t>(entries.size()));
    entries.clear();
  }
  chunks_.push_back(std::move(info));
  chunk_.clear();
  chunk_empty_ = true;
}

void BagWriter::close() {
  if (!file_) return;
  flush_chunk();
  const uint64_t index_pos = pos_;
  for (uint32_t c = 0; c < connections_.size(); ++c) {
    const std::vector<uint8_t> r = connection_record(c);
    put(r.data(), r.size());
  }
  for (const auto& ci : chunks_) {
    std::vector<uint8_t> h, d, rec;
    field_of<uint8_t>(h, "op", kOpChunkInfo);
    field_of<uint32_t>(h, "ver", 1);
    field_of<uint64_t>(h, "chunk_pos", ci.pos);
    field_time(h, "start_time", ci.start);
    field_time(h, "end_time", ci.end);
    field_of<uint32_t>(h, "count", static_cast<uint32_t>(ci.counts.size()));
    for (const auto& [conn, n] : ci.counts) {
      append_raw<uint32_t>(d, conn);
      append_raw<uint32_t>(d, n);
    }
    record(rec, h, d);
    put(rec.data(), rec.size());
  }
  if (std::fseek(file_, 13, SEEK_SET) != 0) throw Error(path_ + ": seek failed");
  write_file_header(index_pos);
  const bool ok = std::fflush(file_) == 0;
  std::fclose(file_);
  file_ = nullptr;
  if (!ok) throw Error(path_ + ": write failed (disk full?)");
}

}  // namespace magcomp::rosio
