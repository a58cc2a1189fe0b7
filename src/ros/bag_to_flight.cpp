// magcomp ROS layer: rosbag -> flight (in memory, or streamed to an HDF5 file), every record
// checked against the schema.
#include <magcomp/FlightRecord.h>
#include <magcomp/FlightSchema.h>
#include <rosbag/bag.h>
#include <rosbag/view.h>

#include <algorithm>
#include <cstdio>
#include <cstring>
#include <functional>
#include <memory>

#include "bag_conversion.h"
#include "magcomp/core/error.h"
#include "magcomp/core/io/file_io.h"
#include "magcomp/core/io/time_base.h"
#include "magcomp/ros/bag_check.h"
#include "magcomp/ros/bag_converter.h"

namespace magcomp::rosio {

using detail::exists;
using detail::kChunkRows;

namespace {

// The serialised bytes of a bag message, read with every length checked against them (a
// corrupt length in ROS's own deserialiser allocates whatever it says before failing).
class RawMessage {
 public:
  explicit RawMessage(const rosbag::MessageInstance& m) : own_(m.size()) {
    ros::serialization::OStream out(own_.data(), static_cast<uint32_t>(own_.size()));
    m.write(out);
    bytes_ = Span{own_.data(), own_.size()};
  }
  /// The message's bytes where they lie (valid while this object is used).
  RawMessage(const uint8_t* data, size_t size) : bytes_{data, size} {}
  bool u32(uint32_t* v) {
    if (bytes_.size() - pos_ < 4) return false;
    std::memcpy(v, bytes_.data() + pos_, 4);
    pos_ += 4;
    return true;
  }
  bool skip_header() {  // std_msgs/Header: seq, stamp, frame_id; the seq is kept
    uint32_t stamp[2], len;
    if (!u32(&seq_) || !u32(&stamp[0]) || !u32(&stamp[1]) || !u32(&len)) return false;
    return skip(len);
  }
  bool skip(uint64_t n) {
    if (bytes_.size() - pos_ < n) return false;
    pos_ += n;
    return true;
  }
  bool doubles(std::vector<double>* out) {
    uint32_t n;
    if (!u32(&n) || (bytes_.size() - pos_) / 8 < n) return false;
    out->resize(n);
    if (n > 0) std::memcpy(out->data(), bytes_.data() + pos_, 8ull * n);  // empty: no pointer
    pos_ += 8ull * n;
    return true;
  }
  bool strings(std::vector<std::string>* out) {
    uint32_t n;
    if (!u32(&n) || (bytes_.size() - pos_) / 4 < n) return false;
    out->clear();
    for (uint32_t k = 0; k < n; ++k) {
      uint32_t len;
      if (!u32(&len) || bytes_.size() - pos_ < len) return false;
      out->emplace_back(reinterpret_cast<const char*>(bytes_.data() + pos_), len);
      pos_ += len;
    }
    return true;
  }
  uint32_t seq() const { return seq_; }

 private:
  struct Span {
    const uint8_t* p;
    size_t n;
    size_t size() const { return n; }
    const uint8_t* data() const { return p; }
  };
  std::vector<uint8_t> own_;
  Span bytes_{nullptr, 0};
  size_t pos_ = 0;
  uint32_t seq_ = 0;
};

}  // namespace

namespace {

// The field names of a bag's schema message.
std::vector<std::string> schema_names(RawMessage& raw, const std::string& bag_path) {
  std::vector<std::string> names;
  if (!raw.skip_header() || !raw.strings(&names)) {
    throw Error(bag_path + ": the message on '" + BagTopics::kSchema + "' is corrupt");
  }
  return names;
}

Error no_schema(const std::string& bag_path) {
  return Error(bag_path + ": topic '" + BagTopics::kSchema +
               "' not found: only bags written by magcomp convert can be turned back into flights");
}

// The values of record `index` into *values, as many as the schema names; returns its sequence
// number.
uint32_t record_values(RawMessage& raw, const std::string& bag_path, long index, size_t fields,
                       std::vector<double>* values) {
  if (!raw.skip_header() || !raw.doubles(values)) {
    throw Error(bag_path + ": record " + std::to_string(index) + " on '" + BagTopics::kRecord +
                "' is corrupt");
  }
  if (values->size() != fields) {
    throw Error(bag_path + ": a record on '" + BagTopics::kRecord + "' has " +
                std::to_string(values->size()) + " values, the schema names " +
                std::to_string(fields));
  }
  return raw.seq();
}

Error records_missing(const std::string& bag_path, long listed, long held) {
  return Error(bag_path + ": the index lists " + std::to_string(listed) + " records on '" +
               BagTopics::kRecord + "', the bag holds " + std::to_string(held));
}

// A bag written by flight_to_bag, read back record by record: the schema's field names, the
// number of records, then each record's values in order (every length and sequence number
// checked). Throws magcomp::Error naming the file.
class RecordReader {
 public:
  explicit RecordReader(const std::string& bag_path) : path_(bag_path) {
    if (!exists(bag_path)) throw Error(bag_path + ": file not found or not readable");
    check_bag_structure(bag_path);
    try {
      bag_.open(bag_path, rosbag::bagmode::Read);
    } catch (const rosbag::BagException& e) {
      throw Error(bag_path + ": not a readable rosbag (" + e.what() + ")");
    }
    {
      rosbag::View v(bag_, rosbag::TopicQuery(std::string(BagTopics::kSchema)));
      for (const auto& m : v) {
        if (m.getDataType() != "magcomp/FlightSchema") continue;
        RawMessage raw(m);
        names_ = schema_names(raw, bag_path);
        break;
      }
    }
    if (names_.empty()) throw no_schema(bag_path);
    records_ = std::make_unique<rosbag::View>(bag_, [](const rosbag::ConnectionInfo* c) {
      return c->topic == BagTopics::kRecord && c->datatype == "magcomp/FlightRecord";
    });
  }
  const std::vector<std::string>& names() const { return names_; }
  /// Records in the bag's index.
  long records() const { return static_cast<long>(records_->size()); }
  /// Calls each(index, values) for every record in order.
  void for_each(const std::function<void(long, const std::vector<double>&)>& each) {
    long expected_seq = 0;
    std::vector<double> values;
    for (const auto& m : *records_) {
      RawMessage raw(m);
      if (static_cast<long>(record_values(raw, path_, expected_seq, names_.size(), &values)) !=
          expected_seq) {
        throw Error(path_ + ": record " + std::to_string(expected_seq) +
                    " missing or out of order on '" + BagTopics::kRecord + "'");
      }
      each(expected_seq++, values);
    }
    if (expected_seq != records()) throw records_missing(path_, records(), expected_seq);
  }

 private:
  std::string path_;
  rosbag::Bag bag_;
  std::vector<std::string> names_;
  std::unique_ptr<rosbag::View> records_;
};

// Runs a conversion step, naming the file on anything rosbag or the deserialiser throws.
template <class F>
auto naming_bag_errors(const std::string& bag_path, F&& f) {
  try {
    return f();
  } catch (const Error&) {
    throw;
  } catch (const std::exception& e) {
    throw Error(bag_path + ": not a readable rosbag (" + e.what() + ")");
  }
}

}  // namespace

FlightData bag_to_flight(const std::string& bag_path) {
  return naming_bag_errors(bag_path, [&] {
    RecordReader reader(bag_path);
    const size_t fields = reader.names().size();
    std::vector<Eigen::VectorXd> cols(fields, Eigen::VectorXd(reader.records()));
    reader.for_each([&](long i, const std::vector<double>& values) {
      for (size_t c = 0; c < fields; ++c) cols[c][i] = values[c];
    });
    FlightData f;
    f.set_source(bag_path);
    for (size_t c = 0; c < fields; ++c) f.set(reader.names()[c], std::move(cols[c]));
    return f;
  });
}

namespace {

// A bag the streaming reader cannot take in one pass (compressed chunks, records out of order in
// the file): it is read through rosbag's index instead.
struct NeedsIndex {};

// The schema and records of a bag written by flight_to_bag, handed over in file order while the
// bag is checked, written to an HDF5 flight file a block of rows at a time.
class RecordsToH5 : public BagVisitor {
 public:
  RecordsToH5(std::string bag_path, std::string h5_path)
      : bag_(std::move(bag_path)), h5_(std::move(h5_path)) {}

  bool wants(const std::string& topic, const std::string& type) override {
    return (topic == BagTopics::kSchema && type == "magcomp/FlightSchema") ||
           (topic == BagTopics::kRecord && type == "magcomp/FlightRecord");
  }
  void counted(const std::string& topic, uint64_t messages) override {
    if (topic == BagTopics::kRecord) records_ = static_cast<long>(messages);
  }
  void message(const std::string& topic, const uint8_t* data, uint64_t size) override {
    RawMessage raw(data, size);
    if (topic == BagTopics::kSchema) {
      if (names_.empty()) names_ = schema_names(raw, bag_);  // the first schema
      return;
    }
    if (names_.empty()) throw NeedsIndex{};  // a record before the schema in the file
    if (!writer_) start();
    const long seq = record_values(raw, bag_, seq_, names_.size(), &values_);
    if (seq != seq_ || seq_ >= records_) throw NeedsIndex{};
    const long row = seq_ - first_;
    for (size_t c = 0; c < columns_.size(); ++c) block_[c][row] = values_[from_[c]];
    tt_[seq_] = values_[from_[tt_column_]];
    if (++seq_ - first_ == kChunkRows) flush();
  }

  /// After the walk: the last rows, N and dt, and the file put in place.
  ConvertReport finish() {
    if (names_.empty()) throw no_schema(bag_);
    if (!writer_) start();
    if (seq_ != records_) throw records_missing(bag_, records_, seq_);
    flush();
    FlightData times;
    times.set("tt", std::move(tt_));
    writer_->finish(records_ > 1 ? times.dt_s() : 0.1);
    ConvertReport rep;
    rep.samples = records_;
    rep.fields = static_cast<long>(names_.size());
    return rep;
  }

 private:
  void start() {
    for (size_t c = 0; c < names_.size(); ++c) {
      if (names_[c] == "N" || names_[c] == "dt") continue;  // the writer writes them
      columns_.push_back(names_[c]);
      from_.push_back(c);
    }
    const auto tt_at = std::find(columns_.begin(), columns_.end(), "tt");
    if (tt_at == columns_.end()) throw Error(bag_ + ": field 'tt' not found");
    tt_column_ = static_cast<size_t>(tt_at - columns_.begin());
    writer_ =
        std::make_unique<FlightH5Writer>(h5_, columns_, records_, std::vector<std::string>{bag_});
    block_.assign(columns_.size(), Eigen::VectorXd(kChunkRows));
    tt_.resize(records_);
  }
  void flush() {
    for (size_t c = 0; c < columns_.size(); ++c)
      writer_->write_rows(c, first_, seq_ - first_, block_[c].data());
    first_ = seq_;
  }

  std::string bag_, h5_;
  std::vector<std::string> names_, columns_;
  std::vector<size_t> from_;  // each column's place in a record
  size_t tt_column_ = 0;
  long records_ = 0, seq_ = 0, first_ = 0;
  std::vector<double> values_;
  std::vector<Eigen::VectorXd> block_;  // a block of rows per column, written when full
  Eigen::VectorXd tt_;                  // the time base, kept whole for the sample period
  std::unique_ptr<FlightH5Writer> writer_;
};

}  // namespace

ConvertReport bag_to_h5(const std::string& bag_path, const std::string& h5_path) {
  if (!exists(bag_path)) throw Error(bag_path + ": file not found or not readable");
  {
    RecordsToH5 sink(bag_path, h5_path);
    try {
      if (check_bag_structure(bag_path, &sink)) return sink.finish();
    } catch (const NeedsIndex&) {
    }
  }  // an unfinished output is removed here
  FlightData f = bag_to_flight(bag_path);
  write_flight_h5(f, h5_path, {bag_path});
  ConvertReport rep;
  rep.samples = f.size();
  rep.fields = static_cast<long>(f.names().size());
  return rep;
}

}  // namespace magcomp::rosio
