// magcomp ROS layer: a structural check of a bag file (format 2.0) before rosbag reads it.
#include "magcomp/ros/bag_check.h"

#include <fcntl.h>
#include <sys/mman.h>
#include <sys/stat.h>
#include <unistd.h>

#include <cstdint>
#include <cstring>
#include <map>
#include <vector>

#include "bag_record_ops.h"
#include "magcomp/core/error.h"
#include "magcomp/core/io/file_io.h"

namespace magcomp::rosio {
namespace {

// Records larger than this are not what any recorder writes (rosbag's chunks are ~768 kB).
constexpr uint64_t kMaxRecordBytes = 1ull << 31;
// An uncompressed chunk larger than this is refused before it is inflated (rosbag writes 768 kB,
// magcomp convert 4 MB).
constexpr uint64_t kMaxChunkBytes = 256ull << 20;

// A view of bytes with bounds-checked reads.
class Bytes {
 public:
  Bytes(const uint8_t* p, uint64_t n) : p_(p), n_(n) {}
  uint64_t size() const { return n_; }
  bool has(uint64_t at, uint64_t len) const { return at <= n_ && len <= n_ - at; }
  uint32_t u32(uint64_t at) const {
    uint32_t v;
    std::memcpy(&v, p_ + at, 4);
    return v;
  }
  uint64_t u64(uint64_t at) const {
    uint64_t v;
    std::memcpy(&v, p_ + at, 8);
    return v;
  }
  const uint8_t* at(uint64_t i) const { return p_ + i; }

 private:
  const uint8_t* p_;
  uint64_t n_;
};

struct Record {
  std::map<std::string, std::string> fields;
  uint64_t data_pos = 0, data_len = 0, end = 0;
  uint8_t op() const {
    auto it = fields.find("op");
    return it != fields.end() && it->second.size() == 1 ? static_cast<uint8_t>(it->second[0]) : 0;
  }
};

class Checker {
 public:
  Checker(const std::string& path, Bytes b) : path_(path), b_(b) {}

  [[noreturn]] void fail(uint64_t at, const std::string& why) const {
    throw Error(path_ + ": not a readable rosbag: " + why + " (at byte " + std::to_string(at) +
                ")");
  }

  Record record(const Bytes& b, uint64_t at) const {
    Record r;
    if (!b.has(at, 4)) fail(at, "record header length past the end");
    const uint32_t hlen = b.u32(at);
    if (!b.has(at + 4, hlen)) fail(at, "record header past the end");
    uint64_t p = at + 4;
    const uint64_t hend = at + 4 + hlen;
    while (p < hend) {
      if (!b.has(p, 4) || p + 4 > hend) fail(p, "header field length past the header");
      const uint32_t flen = b.u32(p);
      p += 4;
      if (flen > hend - p) fail(p, "header field past the header");
      const char* f = reinterpret_cast<const char*>(b.at(p));
      const void* eq = std::memchr(f, '=', flen);
      if (!eq) fail(p, "header field without '='");
      const size_t name_len = static_cast<size_t>(static_cast<const char*>(eq) - f);
      r.fields[std::string(f, name_len)] = std::string(f + name_len + 1, flen - name_len - 1);
      p += flen;
    }
    if (!b.has(hend, 4)) fail(hend, "record data length past the end");
    r.data_len = b.u32(hend);
    r.data_pos = hend + 4;
    if (r.data_len > kMaxRecordBytes || !b.has(r.data_pos, r.data_len)) {
      fail(hend, "record data past the end");
    }
    r.end = r.data_pos + r.data_len;
    if (r.fields.find("op") == r.fields.end() || r.fields["op"].size() != 1)
      fail(at, "record without an op code");
    return r;
  }

  // A connection record's data is itself a header (topic, type, md5sum, message_definition):
  // rosbag parses it with ros::Header, which trusts each field's length. Returns its type.
  std::string check_header_bytes(const Bytes& b, uint64_t from, uint64_t len, uint64_t at) const {
    uint64_t p = from;
    const uint64_t end = from + len;
    std::string type;
    while (p < end) {
      if (end - p < 4) fail(at, "connection header field length past its end");
      const uint32_t flen = b.u32(p);
      p += 4;
      if (flen > end - p) fail(at, "connection header field past its end");
      const char* f = reinterpret_cast<const char*>(b.at(p));
      if (!std::memchr(f, '=', flen)) fail(at, "connection header field without '='");
      if (flen >= 5 && std::memcmp(f, "type=", 5) == 0) type.assign(f + 5, flen - 5);
      p += flen;
    }
    return type;
  }

  uint64_t field_u(const Record& r, const std::string& name, size_t bytes, uint64_t at) const {
    auto it = r.fields.find(name);
    if (it == r.fields.end() || it->second.size() != bytes)
      fail(at, "record field '" + name + "' missing or of the wrong size");
    uint64_t v = 0;
    std::memcpy(&v, it->second.data(), bytes);
    return v;
  }

  // The records inside an uncompressed chunk: connections and messages, and nothing past it.
  void check_chunk_content(uint64_t base, const Bytes& c) const {
    uint64_t p = 0;
    while (p < c.size()) {
      const Record r = record(c, p);
      if (r.op() != kOpMessage && r.op() != kOpConnection)
        fail(base + p, "unexpected record in a chunk");
      if (r.op() == kOpConnection) check_header_bytes(c, r.data_pos, r.data_len, base + p);
      if (r.op() == kOpMessage) {
        const uint64_t conn = field_u(r, "conn", 4, base + p);
        auto it = connections_.find(static_cast<uint32_t>(conn));
        if (it == connections_.end())
          fail(base + p, "message on an unknown connection " + std::to_string(conn));
        if (visitor_ && it->second.wanted)
          visitor_->message(it->second.topic, c.at(r.data_pos), r.data_len);
      }
      p = r.end;
    }
  }

  // Lets the process's memory go of the file's bytes [from, to) (read, no longer needed).
  void release(uint64_t from, uint64_t to) const {
    const uint64_t page = static_cast<uint64_t>(::sysconf(_SC_PAGESIZE));
    const uint64_t a = (from + page - 1) / page * page, z = to / page * page;
    if (z > a) ::madvise(const_cast<uint8_t*>(b_.at(a)), z - a, MADV_DONTNEED);
  }

  bool run(BagVisitor* visitor) {
    visitor_ = visitor;
    bool all_delivered = true;
    static const char kMagic[] = "#ROSBAG V2.0\n";
    if (!b_.has(0, 13) || std::memcmp(b_.at(0), kMagic, 13) != 0)
      fail(0, "no '#ROSBAG V2.0' version line");
    const Record h = record(b_, 13);
    if (h.op() != kOpBagHeader) fail(13, "the first record is not the bag header");
    const uint64_t index_pos = field_u(h, "index_pos", 8, 13);
    const uint64_t conn_count = field_u(h, "conn_count", 4, 13);
    const uint64_t chunk_count = field_u(h, "chunk_count", 4, 13);
    if (index_pos == 0) fail(13, "the bag was not closed (no index)");
    if (index_pos < h.end || index_pos >= b_.size()) fail(13, "index position outside the file");
    uint64_t p = index_pos;
    for (uint64_t k = 0; k < conn_count; ++k) {
      const Record r = record(b_, p);
      if (r.op() != kOpConnection) fail(p, "expected a connection record in the index");
      if (!r.fields.count("topic")) fail(p, "connection without a topic");
      Connection& c = connections_[static_cast<uint32_t>(field_u(r, "conn", 4, p))];
      c.topic = r.fields.at("topic");
      const std::string type = check_header_bytes(b_, r.data_pos, r.data_len, p);
      c.wanted = visitor_ && visitor_->wants(c.topic, type);
      p = r.end;
    }
    if (visitor_) {  // the wanted messages the chunk infos count (conn, count pairs), by topic
      std::map<std::string, uint64_t> wanted;
      for (const auto& [id, c] : connections_) {
        if (c.wanted) wanted[c.topic];
      }
      uint64_t q = p;
      for (uint64_t k = 0; k < chunk_count; ++k) {
        const Record info = record(b_, q);
        if (info.op() != kOpChunkInfo) fail(q, "expected a chunk info record in the index");
        for (uint64_t e = 0; e + 8 <= info.data_len; e += 8) {
          auto it = connections_.find(b_.u32(info.data_pos + e));
          if (it != connections_.end() && it->second.wanted)
            wanted[it->second.topic] += b_.u32(info.data_pos + e + 4);
        }
        q = info.end;
      }
      for (const auto& [topic, n] : wanted) visitor_->counted(topic, n);
    }
    for (uint64_t k = 0; k < chunk_count; ++k) {
      const Record info = record(b_, p);
      if (info.op() != kOpChunkInfo) fail(p, "expected a chunk info record in the index");
      const uint64_t chunk_pos = field_u(info, "chunk_pos", 8, p);
      const uint64_t count = field_u(info, "count", 4, p);
      if (info.data_len != count * 8) fail(p, "chunk info data does not match its count");
      if (chunk_pos < h.end || chunk_pos >= index_pos) fail(p, "chunk position outside the data");
      const Record chunk = record(b_, chunk_pos);
      if (chunk.op() != kOpChunk) fail(chunk_pos, "no chunk record where the index points");
      const std::string compression =
          chunk.fields.count("compression") ? chunk.fields.at("compression") : "";
      const uint64_t size = field_u(chunk, "size", 4, chunk_pos);
      if (compression == "none") {
        if (size != chunk.data_len) fail(chunk_pos, "chunk size does not match its data");
        check_chunk_content(chunk.data_pos, Bytes(b_.at(chunk.data_pos), chunk.data_len));
      } else {
        all_delivered = false;  // its messages are rosbag's to inflate
        if (compression != "bz2" && compression != "lz4") {
          fail(chunk_pos, "unknown chunk compression '" + compression + "'");
        } else if (size > kMaxChunkBytes || size < chunk.data_len / 1000) {
          fail(chunk_pos, "compressed chunk of an implausible size (" + std::to_string(size) +
                              " bytes from " + std::to_string(chunk.data_len) + ")");
        }
      }
      // The chunk's index records, right after it.
      uint64_t q = chunk.end;
      for (uint64_t c = 0; c < count; ++c) {
        const Record ix = record(b_, q);
        if (ix.op() != kOpIndex) fail(q, "expected an index record after the chunk");
        const uint64_t n = field_u(ix, "count", 4, q);
        if (ix.data_len != n * 12) fail(q, "index data does not match its count");
        if (compression == "none") {
          for (uint64_t e = 0; e < n; ++e) {
            const uint32_t off = b_.u32(ix.data_pos + e * 12 + 8);
            if (off >= size) fail(q, "index entry points outside its chunk");
          }
        }
        q = ix.end;
      }
      release(chunk_pos, q);
      p = info.end;
    }
    return all_delivered;
  }

 private:
  struct Connection {
    std::string topic;
    bool wanted = false;
  };
  std::string path_;
  Bytes b_;
  std::map<uint32_t, Connection> connections_;
  BagVisitor* visitor_ = nullptr;
};

}  // namespace

bool check_bag_structure(const std::string& path, BagVisitor* visitor) {
  require_regular_file(path, "bag");  // before open(): a pipe would block it
  const int fd = ::open(path.c_str(), O_RDONLY | O_CLOEXEC);
  if (fd < 0) throw Error(path + ": file not found or not readable");
  struct stat st {};
  if (::fstat(fd, &st) != 0 || !S_ISREG(st.st_mode)) {
    ::close(fd);
    throw Error(path + ": not a regular file");
  }
  const auto size = static_cast<uint64_t>(st.st_size);
  if (size == 0) {
    ::close(fd);
    throw Error(path + ": not a readable rosbag: empty file");
  }
  void* map = ::mmap(nullptr, size, PROT_READ, MAP_PRIVATE, fd, 0);
  ::close(fd);
  if (map == MAP_FAILED) throw Error(path + ": cannot read");
  bool all_delivered = true;
  try {
    all_delivered = Checker(path, Bytes(static_cast<const uint8_t*>(map), size)).run(visitor);
  } catch (...) {
    ::munmap(map, size);
    throw;
  }
  ::munmap(map, size);
  return all_delivered;
}

}  // namespace magcomp::rosio
