// magcomp: FlightData columns, selection and subsets.
#include "magcomp/core/io/flight_data.h"

#include <sys/mman.h>
#include <unistd.h>

#include <algorithm>
#include <cfloat>
#include <cmath>
#include <cstdint>
#include <optional>

#include "magcomp/core/error.h"

namespace magcomp {

std::string FlightData::canonical_name(const std::string& name) {
  // Older (2020 first release) names -> final names, DATA.md.
  static const std::unordered_map<std::string, std::string> kAliases = {
      {"tie_line", "line"},       {"utmX", "utm_x"},        {"utmY", "utm_y"},
      {"utmZ", "utm_z"},          {"alt", "msl"},           {"ins_azim", "ins_yaw"},
      {"pitch_rt", "pitch_rate"}, {"roll_rt", "roll_rate"}, {"yaw_rt", "yaw_rate"},
      {"lon_acc", "lgtl_acc"},    {"lat_acc", "ltrl_acc"},  {"alt_acc", "nrml_acc"},
      {"true_as", "tas"},         {"vol_servo", "vol_srvo"}};
  auto it = kAliases.find(name);
  return it == kAliases.end() ? name : it->second;
}

// Keys are always stored canonical, so a name found as it is needs no alias lookup (the common
// case, and a per-sample one for the streaming compensator).
bool FlightData::has(const std::string& name) const {
  return index_.count(name) > 0 || index_.count(canonical_name(name)) > 0;
}

size_t FlightData::index_of(const std::string& name) const {
  auto it = index_.find(name);
  if (it == index_.end()) it = index_.find(canonical_name(name));
  if (it == index_.end()) throw Error(source_ + ": field '" + name + "' not found");
  return it->second;
}

void FlightData::try_map(size_t i) const {
  Lazy& z = lazy_[i];
  if (!z.loader || z.map_tried) return;
  z.mapped = z.loader->map(z.stored_name);
  z.map_tried = true;
}

FlightData::Column FlightData::column(const std::string& name) const {
  const size_t i = index_of(name);
  ensure_loaded(i);
  return Column(values(i), size_);
}

Eigen::VectorXd FlightData::column_rows(const std::string& name, Eigen::Index first,
                                        Eigen::Index count) const {
  const size_t i = index_of(name);
  if (first < 0 || count < 0 || first + count > size_) {
    throw Error(source_ + ": field '" + name + "': rows outside the flight");
  }
  {
    // The read itself under the lock too: the HDF5 library is not thread-safe, and a slice's
    // loader may read through its parent's.
    std::lock_guard<std::mutex> lock(*load_mutex_);
    Lazy& z = lazy_[i];
    try_map(i);
    if (z.mapped) {  // in place: only these rows' pages are read
      return Eigen::Map<const Eigen::VectorXd>(z.mapped + first, count);
    }
    // Up to twice the column in parts (blocks overlap by their margins), then it is loaded.
    if (z.loader && z.loader->reads_rows() && z.rows_read_in_part + count <= 2 * size_) {
      z.rows_read_in_part += count;
      Eigen::VectorXd v = z.loader->load_rows(z.stored_name, first, count);
      if (v.size() != count) {
        throw Error(source_ + ": field '" + names_[i] + "': " + std::to_string(v.size()) +
                    " samples read, expected " + std::to_string(count));
      }
      return v;
    }
  }
  ensure_loaded(i);
  return Column(values(i), size_).segment(first, count);
}

const double* FlightData::values_in_place(const std::string& name) const {
  const size_t i = index_of(name);
  std::lock_guard<std::mutex> lock(*load_mutex_);
  try_map(i);
  const Lazy& z = lazy_[i];
  if (z.mapped) return z.mapped;
  return z.loader ? nullptr : columns_[i].data();
}

void FlightData::ensure_loaded(size_t i) const {
  std::lock_guard<std::mutex> lock(*load_mutex_);
  Lazy& z = lazy_[i];
  if (!z.loader) return;
  try_map(i);
  if (z.mapped) {
    z.mapping = std::move(z.loader);
    z.loader.reset();
    return;
  }
  Eigen::VectorXd v = z.loader->load(z.stored_name);
  if (v.size() != size_) {
    throw Error(source_ + ": field '" + names_[i] + "' has " + std::to_string(v.size()) +
                " samples, expected " + std::to_string(size_));
  }
  columns_[i] = std::move(v);
  z.loader.reset();
}

void FlightData::set_lazy(const std::string& name, std::string stored_name,
                          std::shared_ptr<const ColumnLoader> loader, Eigen::Index size) {
  if (size_ < 0 && size >= 0) size_ = size;
  if (size_ < 0) throw Error(source_ + ": field '" + name + "' declared before the time base");
  if (size >= 0 && size != size_) {
    throw Error(source_ + ": field '" + name + "' has " + std::to_string(size) +
                " samples, expected " + std::to_string(size_));
  }
  const std::string key = canonical_name(name);
  if (key == "tt") dt_cache_.s.store(std::numeric_limits<double>::quiet_NaN());
  auto it = index_.find(key);
  size_t i;
  if (it != index_.end()) {
    i = it->second;
  } else {
    i = names_.size();
    index_[key] = i;
    names_.push_back(key);
    columns_.emplace_back();
    lazy_.emplace_back();
  }
  columns_[i] = Eigen::VectorXd();
  lazy_[i] = Lazy{};
  lazy_[i].stored_name = std::move(stored_name);
  lazy_[i].loader = std::move(loader);
}

size_t FlightData::loaded_columns() const {
  std::lock_guard<std::mutex> lock(*load_mutex_);
  size_t n = 0;
  for (const auto& z : lazy_) n += !z.loader;
  return n;
}

void FlightData::drop_mapped_pages(Eigen::Index end_row) const {
  std::lock_guard<std::mutex> lock(*load_mutex_);
  const uintptr_t page = static_cast<uintptr_t>(::sysconf(_SC_PAGESIZE));
  const Eigen::Index rows = end_row < 0 ? size_ : std::min(end_row, size_);
  for (const Lazy& z : lazy_) {
    if (!z.mapped) continue;
    // Whole pages inside the rows only: a page shared with a neighbour stays.
    const uintptr_t begin = (reinterpret_cast<uintptr_t>(z.mapped) + page - 1) / page * page;
    const uintptr_t end = reinterpret_cast<uintptr_t>(z.mapped + rows) / page * page;
    if (end > begin) ::madvise(reinterpret_cast<void*>(begin), end - begin, MADV_DONTNEED);
  }
}

Eigen::VectorXd& FlightData::mutable_column(const std::string& name) {
  const size_t i = index_of(name);
  if (names_[i] == "tt") dt_cache_.s.store(std::numeric_limits<double>::quiet_NaN());
  ensure_loaded(i);
  Lazy& z = lazy_[i];
  if (z.mapped) {  // a copy of its own from now on
    columns_[i] = Column(z.mapped, size_);
    z = Lazy{};
  }
  return columns_[i];
}

void FlightData::set(const std::string& name, Eigen::VectorXd values) {
  const std::string key = canonical_name(name);
  if (key == "tt") dt_cache_.s.store(std::numeric_limits<double>::quiet_NaN());
  if (size_ < 0 || names_.empty()) {
    size_ = values.size();
  } else if (values.size() != size_) {
    throw Error(source_ + ": field '" + key + "' has " + std::to_string(values.size()) +
                " samples, expected " + std::to_string(size_));
  }
  auto it = index_.find(key);
  if (it != index_.end()) {
    columns_[it->second] = std::move(values);
    lazy_[it->second] = Lazy{};
    return;
  }
  index_[key] = names_.size();
  names_.push_back(key);
  columns_.push_back(std::move(values));
  lazy_.emplace_back();
}

void FlightData::remove(const std::string& name) {
  auto it = index_.find(canonical_name(name));
  if (it == index_.end()) return;
  if (it->first == "tt") dt_cache_.s.store(std::numeric_limits<double>::quiet_NaN());
  const size_t pos = it->second;
  names_.erase(names_.begin() + static_cast<std::ptrdiff_t>(pos));
  columns_.erase(columns_.begin() + static_cast<std::ptrdiff_t>(pos));
  lazy_.erase(lazy_.begin() + static_cast<std::ptrdiff_t>(pos));
  index_.clear();
  for (size_t i = 0; i < names_.size(); ++i) index_[names_[i]] = i;
}

namespace {

// The sample period's defining statistic: the element of rank size/2 (0-based) of tt's positive,
// finite steps. A regularly sampled tt takes a few step values, so candidates are the distinct
// values of a sample of the steps, tried in order from their middle: one counting pass (no
// storage) tells whether a candidate has the rank, or on which side of it the rank lies. Without
// a confirmed candidate after a few passes the steps are stored and partially sorted.
double median_step_s(const FlightData::Column& t, const std::string& source) {
  const Eigen::Index n = t.size();
  const double* tt = t.data();
  std::vector<double> sample;
  constexpr Eigen::Index kSample = 31;
  for (Eigen::Index k = 0; n > 2 && k < kSample; ++k) {
    const Eigen::Index i = 1 + k * (n - 2) / (kSample - 1);
    const double d = tt[i] - tt[i - 1];
    if (d > 0 && d <= DBL_MAX) sample.push_back(d);
  }
  std::sort(sample.begin(), sample.end());
  sample.erase(std::unique(sample.begin(), sample.end()), sample.end());
  auto candidate = static_cast<std::ptrdiff_t>(sample.size() / 2);
  for (int pass = 0; pass < 4 && candidate >= 0 && candidate < std::ptrdiff_t(sample.size());
       ++pass) {
    const double c = sample[static_cast<size_t>(candidate)];
    int64_t count = 0, below = 0, equal = 0;
    for (Eigen::Index i = 1; i < n; ++i) {
      const double d = tt[i] - tt[i - 1];
      const int64_t usable = d > 0 && d <= DBL_MAX;
      count += usable;
      below += usable & (d < c);
      equal += usable & (d == c);
    }
    const int64_t rank = count / 2;
    if (rank < below) {
      --candidate;
    } else if (rank >= below + equal) {
      ++candidate;
    } else {
      return c;
    }
  }
  std::vector<double> steps;
  steps.reserve(static_cast<size_t>(std::max<Eigen::Index>(0, n - 1)));
  for (Eigen::Index i = 1; i < n; ++i) {
    const double d = tt[i] - tt[i - 1];
    if (d > 0 && std::isfinite(d)) steps.push_back(d);
  }
  if (steps.empty()) throw Error(source + ": field 'tt' has no two increasing samples");
  auto mid = steps.begin() + static_cast<std::ptrdiff_t>(steps.size() / 2);
  std::nth_element(steps.begin(), mid, steps.end());
  return *mid;
}

}  // namespace

double FlightData::dt_s() const {
  const double cached = dt_cache_.s.load();
  if (!std::isnan(cached)) return cached;
  const double dt = median_step_s(tt(), source_);
  dt_cache_.s.store(dt);
  return dt;
}

std::vector<Eigen::Index> FlightData::select(const std::vector<double>& lines,
                                             const std::vector<TimeWindow>& windows) const {
  std::vector<Eigen::Index> out;
  const Column t = tt();
  const std::optional<Column> line =
      lines.empty() ? std::nullopt : std::optional<Column>(column("line"));
  for (Eigen::Index i = 0; i < size_; ++i) {
    bool take = false;
    if (line) {
      for (double l : lines) {
        if (std::abs((*line)[i] - l) < 1e-6) {
          take = true;
          break;
        }
      }
    }
    if (!take) {
      for (const TimeWindow& w : windows) {
        if (t[i] >= w.start_s && t[i] <= w.end_s) {
          take = true;
          break;
        }
      }
    }
    if (take) out.push_back(i);
  }
  return out;
}

FlightData FlightData::subset(const std::vector<Eigen::Index>& indices) const {
  FlightData out;
  out.source_ = source_;
  const Eigen::Index n = static_cast<Eigen::Index>(indices.size());
  for (size_t c = 0; c < names_.size(); ++c) {
    ensure_loaded(c);
    const double* x = values(c);
    Eigen::VectorXd v(n);
    for (Eigen::Index k = 0; k < n; ++k) v[k] = x[indices[static_cast<size_t>(k)]];
    out.set(names_[c], std::move(v));
  }
  if (names_.empty()) out.size_ = 0;
  return out;
}

namespace {
// Reads a column's rows [first, first + count) from the flight a slice came from.
class RowsLoader : public ColumnLoader {
 public:
  RowsLoader(const FlightData* parent, Eigen::Index first, Eigen::Index count)
      : parent_(parent), first_(first), count_(count) {}
  Eigen::VectorXd load(const std::string& name) const override {
    return parent_->column_rows(name, first_, count_);
  }
  // The parent's rows where they lie, when they need no copy.
  const double* map(const std::string& name) const override {
    const double* values = parent_->values_in_place(name);
    return values ? values + first_ : nullptr;
  }

 private:
  const FlightData* parent_;
  Eigen::Index first_, count_;
};
}  // namespace

FlightData FlightData::rows(Eigen::Index first, Eigen::Index count) const {
  if (first < 0 || count < 0 || first + count > size_) {
    throw Error(source_ + ": rows [" + std::to_string(first) + ", " +
                std::to_string(first + count) + ") outside the flight's " + std::to_string(size_) +
                " samples");
  }
  FlightData out;
  out.source_ = source_;
  out.size_ = count;
  const double dt = dt_s();
  auto loader = std::make_shared<const RowsLoader>(this, first, count);
  for (const std::string& name : names_) out.set_lazy(name, name, loader);
  out.dt_cache_.s.store(dt);
  return out;
}

std::vector<std::pair<Eigen::Index, Eigen::Index>> FlightData::contiguous_runs(
    const std::vector<Eigen::Index>& indices, double max_gap_s) const {
  std::vector<std::pair<Eigen::Index, Eigen::Index>> runs;
  if (indices.empty()) return runs;
  const Column t = tt();
  Eigen::Index first = indices[0];
  Eigen::Index prev = indices[0];
  for (size_t k = 1; k < indices.size(); ++k) {
    const Eigen::Index i = indices[k];
    if (i != prev + 1 || !(t[i] - t[prev] <= max_gap_s)) {
      runs.emplace_back(first, prev);
      first = i;
    }
    prev = i;
  }
  runs.emplace_back(first, prev);
  return runs;
}

}  // namespace magcomp
