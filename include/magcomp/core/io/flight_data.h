// magcomp: a flight as named float64 columns sampled on one time base (MIT challenge schema).
#pragma once

#include <Eigen/Core>
#include <atomic>
#include <cstdint>
#include <limits>
#include <memory>
#include <mutex>
#include <string>
#include <unordered_map>
#include <utility>
#include <vector>

namespace magcomp {

/// A time window [start_s, end_s] in seconds past midnight UTC (the `tt` base), both ends included.
struct TimeWindow {
  double start_s = 0.0;
  double end_s = 0.0;
};

/// Reads the values of a column on first use (a file opened by read_flight_h5), in the flight's
/// sample order. Throws magcomp::Error naming the file and field.
class ColumnLoader {
 public:
  virtual ~ColumnLoader() = default;
  virtual Eigen::VectorXd load(const std::string& stored_name) const = 0;
  /// The column's values in place (a file mapped into memory, already in sample order), valid
  /// as long as this loader lives; nullptr when they must be read by load(). Throws
  /// magcomp::Error naming the file and field when the stored values cannot be what the file
  /// declares.
  virtual const double* map(const std::string& /*stored_name*/) const { return nullptr; }
  /// True when load_rows() reads only the rows asked for (a sorted file).
  virtual bool reads_rows() const { return false; }
  /// Samples [first, first + count) of a column, in sample order.
  virtual Eigen::VectorXd load_rows(const std::string& stored_name, Eigen::Index first,
                                    Eigen::Index count) const {
    return load(stored_name).segment(first, count);
  }
};

/// One flight: N samples of named float64 columns, one of which is `tt` (s past midnight UTC).
/// Column names are the final MIT names (DATA.md); older names are renamed on read. NaN is kept.
/// A flight read from a file loads each column on first use: a command reads only the fields it
/// touches (thread-safe); a column stored plainly (contiguous float64) is not copied at all but
/// read in place from the file mapped into memory.
class FlightData {
 public:
  /// A column's N values, read-only, in the field's unit; valid while this flight (or a copy of
  /// it) lives and the column is not replaced.
  using Column = Eigen::Map<const Eigen::VectorXd>;

  FlightData() = default;

  /// Number of samples.
  Eigen::Index size() const { return size_; }
  /// Column names in insertion order.
  const std::vector<std::string>& names() const { return names_; }
  /// True if the column exists (final name, or an older alias of it).
  bool has(const std::string& name) const;
  /// Column by name (older aliases accepted). Throws magcomp::Error naming `source()` and the
  /// field.
  Column column(const std::string& name) const;
  /// Samples [first, first + count) of a column (a copy). A column not yet in memory is read
  /// in part from its file, until the parts read add up to twice the column; then it is loaded.
  Eigen::VectorXd column_rows(const std::string& name, Eigen::Index first,
                              Eigen::Index count) const;
  /// Where a column's values lie when they need no copy: in memory already or read in place
  /// from the file (nullptr when the column must be read into memory first). Same lookup rules;
  /// valid as column()'s view is.
  const double* values_in_place(const std::string& name) const;
  /// The column to change in place (a copy in memory from then on if it was read in place from
  /// its file); same lookup rules.
  Eigen::VectorXd& mutable_column(const std::string& name);
  /// Adds or replaces a column; its length must equal size() (the first column fixes the size).
  void set(const std::string& name, Eigen::VectorXd values);
  /// Declares a column whose values `loader` reads on first use (stored_name: its name in the
  /// source). The size must already be known (set tt first) or be given as `size`.
  void set_lazy(const std::string& name, std::string stored_name,
                std::shared_ptr<const ColumnLoader> loader, Eigen::Index size = -1);
  /// Columns whose values are in memory.
  size_t loaded_columns() const;
  /// Lets go of the pages of the columns read in place from their file: they leave this
  /// process's resident memory (the system's file cache keeps them) and are mapped again, with
  /// the same values, on the next access. A job calls it between passes over different columns
  /// to bound its memory; a streaming pass calls it for the rows [0, end) behind it.
  void drop_mapped_pages(Eigen::Index end = -1) const;
  /// Removes a column if present.
  void remove(const std::string& name);

  /// Time base `tt` in s past midnight UTC.
  Column tt() const { return column("tt"); }
  /// Sample period in s, the median of the positive tt differences (never the file's `dt`);
  /// computed once per time base.
  double dt_s() const;

  /// Samples whose `line` equals one of `lines` (compared to 1e-6) or whose tt falls in one of
  /// `windows`. Returns the sample indices, sorted. Empty lists select nothing.
  std::vector<Eigen::Index> select(const std::vector<double>& lines,
                                   const std::vector<TimeWindow>& windows) const;
  /// A new flight holding only the given samples (indices into this one).
  FlightData subset(const std::vector<Eigen::Index>& indices) const;
  /// Samples [first, first + count) as a flight whose columns are read from this one on first
  /// use, in place where this one holds them in memory or maps them (this flight must outlive it
  /// and keep its columns unchanged meanwhile); its dt_s() is this flight's, so anything computed
  /// on the slice equals the same rows computed on the whole flight wherever it depends only on
  /// rows inside the slice.
  FlightData rows(Eigen::Index first, Eigen::Index count) const;
  /// Splits sorted sample indices into runs of consecutive samples with no time gap over
  /// `max_gap_s`. Each run is [first, last] inclusive.
  std::vector<std::pair<Eigen::Index, Eigen::Index>> contiguous_runs(
      const std::vector<Eigen::Index>& indices, double max_gap_s) const;

  /// Where the data came from (a file path), used in error messages.
  const std::string& source() const { return source_; }
  void set_source(std::string source) { source_ = std::move(source); }
  /// What the reader left out or repaired and why (a string dataset, samples sorted by tt), one
  /// line each, naming the file and the field.
  const std::vector<std::string>& read_notes() const { return read_notes_; }
  void add_read_note(std::string note) { read_notes_.push_back(std::move(note)); }

  /// Final MIT name for an older one (`tie_line` -> `line`, ...); the name itself otherwise.
  static std::string canonical_name(const std::string& name);

 private:
  /// Loads column i if it is lazy and not loaded yet.
  void ensure_loaded(size_t i) const;
  /// The index of a column (older aliases accepted); throws magcomp::Error naming the field.
  size_t index_of(const std::string& name) const;
  /// Asks column i's loader once whether its values can be used in place (under the lock).
  void try_map(size_t i) const;

  /// Where column i's values are: in columns_[i], or in place in a file mapping (`mapped`, kept
  /// valid by `mapping`).
  const double* values(size_t i) const {
    return lazy_[i].mapped ? lazy_[i].mapped : columns_[i].data();
  }

  Eigen::Index size_ = -1;
  std::vector<std::string> names_;
  mutable std::vector<Eigen::VectorXd> columns_;
  struct Lazy {
    std::string stored_name;
    std::shared_ptr<const ColumnLoader> loader;   // null: in memory or mapped
    Eigen::Index rows_read_in_part = 0;           // by column_rows() while not in memory
    const double* mapped = nullptr;               // the values in place, or null
    bool map_tried = false;                       // loader->map() asked once
    std::shared_ptr<const ColumnLoader> mapping;  // keeps `mapped` valid
  };
  mutable std::vector<Lazy> lazy_;
  std::shared_ptr<std::mutex> load_mutex_ = std::make_shared<std::mutex>();
  /// dt_s() once computed (NaN: not yet); reset whenever tt may change.
  struct CachedPeriod {
    std::atomic<double> s{std::numeric_limits<double>::quiet_NaN()};
    CachedPeriod() = default;
    CachedPeriod(const CachedPeriod& o) : s(o.s.load()) {}
    CachedPeriod& operator=(const CachedPeriod& o) {
      s.store(o.s.load());
      return *this;
    }
  };
  mutable CachedPeriod dt_cache_;
  std::unordered_map<std::string, size_t> index_;
  std::string source_ = "<memory>";
  std::vector<std::string> read_notes_;
};

/// Reads an MIT challenge HDF5 flight file: every top-level 1-D float dataset of length N becomes
/// a column, older names are renamed, scalar `N` / `dt` datasets are tolerated (dt is derived from
/// tt), and samples are sorted by tt. Objects outside the schema (groups, string, boolean,
/// compound datasets, other scalars) are listed in read_notes(), never dropped silently. Throws
/// magcomp::Error naming the file and field on any problem: missing file, not HDF5, no `tt`, a
/// non-finite or sub-microsecond `tt`, wrong rank or length, a size the file cannot hold, an
/// object that cannot be read.
FlightData read_flight_h5(const std::string& path);

/// Writes a flight in the same schema (one float64 1-D dataset per column, plus scalar `N` and
/// `dt`). Writes to a temporary file beside `path` and renames it, so a reader never sees half a
/// file; refuses a path that is one of `inputs` or not a regular file (file_io.h). Throws
/// magcomp::Error naming the file on failure.
void write_flight_h5(const FlightData& data, const std::string& path,
                     const std::vector<std::string>& inputs = {});

/// Writes a flight file of known size a block of rows at a time (the schema of write_flight_h5),
/// so a long flight need not be held whole: the columns are declared first, rows [first, first +
/// count) of each are written in any order, and finish() adds `N` and `dt` and puts the file in
/// place atomically. A writer destroyed unfinished leaves nothing behind. Throws magcomp::Error
/// naming the file on failure.
class FlightH5Writer {
 public:
  /// `names`: the columns in file order; `samples`: their common length; `inputs`: files the
  /// output must not replace (file_io.h).
  FlightH5Writer(std::string path, std::vector<std::string> names, Eigen::Index samples,
                 const std::vector<std::string>& inputs = {});
  ~FlightH5Writer();
  FlightH5Writer(const FlightH5Writer&) = delete;
  FlightH5Writer& operator=(const FlightH5Writer&) = delete;
  /// Rows [first, first + count) of column c (in `names` order): count values at `values`.
  void write_rows(size_t column, Eigen::Index first, Eigen::Index count, const double* values);
  /// Writes the scalars N and dt (the sample period, s) and renames the file into place.
  void finish(double dt_s);

 private:
  void discard();  // closes what is open and removes the temporary file

  std::string path_, tmp_;
  std::vector<std::string> names_;
  std::vector<std::string> inputs_;
  Eigen::Index samples_;
  int64_t file_ = -1;              // the HDF5 file (hid_t)
  std::vector<int64_t> datasets_;  // one per column (hid_t)
};

}  // namespace magcomp
