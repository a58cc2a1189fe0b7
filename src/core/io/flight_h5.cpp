// magcomp: MIT challenge HDF5 flight files, read and write (HDF5 C API).
#include <fcntl.h>
#include <hdf5.h>
#include <sys/mman.h>
#include <sys/wait.h>
#include <unistd.h>

#include <cerrno>

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <fstream>
#include <mutex>
#include <numeric>

#include "h5_link_names.h"
#include "h5_stored_values.h"
#include "magcomp/core/error.h"
#include "magcomp/core/io/file_io.h"
#include "magcomp/core/io/flight_data.h"
#include "magcomp/core/io/h5_probe.h"

namespace magcomp {
namespace {

// Closes an HDF5 identifier on scope exit.
struct H5Handle {
  hid_t id;
  herr_t (*close)(hid_t);
  H5Handle(hid_t i, herr_t (*c)(hid_t)) : id(i), close(c) {}
  ~H5Handle() {
    if (id >= 0) close(id);
  }
  H5Handle(const H5Handle&) = delete;
  H5Handle& operator=(const H5Handle&) = delete;
};

struct Dataset {
  std::string name;
  std::vector<hsize_t> dims;
  Eigen::VectorXd values;
  bool numeric = true;
};

const char* class_name(H5T_class_t c) {
  switch (c) {
    case H5T_STRING:
      return "string";
    case H5T_COMPOUND:
      return "compound";
    case H5T_ENUM:
      return "enum (boolean)";
    case H5T_ARRAY:
      return "array";
    case H5T_BITFIELD:
      return "bitfield";
    case H5T_OPAQUE:
      return "opaque";
    case H5T_REFERENCE:
      return "reference";
    case H5T_VLEN:
      return "variable-length";
    default:
      return "non-numeric";
  }
}

// Opens a dataset and reads its shape; the values are read by read_values once the length is
// checked against tt and the file.
Dataset open_dataset(hid_t file, const std::string& path, const std::string& name,
                     std::string* skip_reason) {
  Dataset d;
  d.name = name;
  H5Handle ds(H5Dopen2(file, name.c_str(), H5P_DEFAULT), H5Dclose);
  if (ds.id < 0) throw Error(path + ": field '" + name + "' cannot be opened (corrupt object)");
  H5Handle type(H5Dget_type(ds.id), H5Tclose);
  if (type.id < 0) throw Error(path + ": field '" + name + "' has an unreadable type");
  const H5T_class_t cls = H5Tget_class(type.id);
  if (cls != H5T_FLOAT && cls != H5T_INTEGER) {
    d.numeric = false;
    *skip_reason = class_name(cls);
    return d;
  }
  H5Handle space(H5Dget_space(ds.id), H5Sclose);
  if (space.id < 0) throw Error(path + ": field '" + name + "' has an unreadable shape");
  const int rank = H5Sget_simple_extent_ndims(space.id);
  if (rank < 0) throw Error(path + ": field '" + name + "' has an unreadable shape");
  d.dims.resize(static_cast<size_t>(rank));
  if (rank > 0 && H5Sget_simple_extent_dims(space.id, d.dims.data(), nullptr) < 0) {
    throw Error(path + ": field '" + name + "' has an unreadable shape");
  }
  return d;
}

// Reads the values of a dataset whose element count is `count`, after checking that the file can
// hold them (no allocation from a declared size alone).
void read_values(hid_t file, const std::string& path, Dataset& d, hsize_t count,
                 hsize_t file_bytes) {
  H5Handle ds(H5Dopen2(file, d.name.c_str(), H5P_DEFAULT), H5Dclose);
  if (ds.id < 0) throw Error(path + ": field '" + d.name + "' cannot be opened (corrupt object)");
  const std::string problem = h5_stored_values_problem(ds.id, count, file_bytes);
  if (!problem.empty()) throw Error(path + ": field '" + d.name + "' " + problem);
  try {
    d.values.resize(static_cast<Eigen::Index>(count));
  } catch (const std::bad_alloc&) {
    throw Error(path + ": field '" + d.name + "': not enough memory for " + std::to_string(count) +
                " values");
  }
  if (count > 0 &&
      H5Dread(ds.id, H5T_NATIVE_DOUBLE, H5S_ALL, H5S_ALL, H5P_DEFAULT, d.values.data()) < 0) {
    throw Error(path + ": field '" + d.name + "' cannot be read as float64 (corrupt data)");
  }
}

// libhdf5 (Debian's serial build) is not thread-safe: every call from a column loader holds this.
std::mutex& hdf5_mutex() {
  static std::mutex m;
  return m;
}

// Reads the other columns of an open file on first use, in the flight's sample order.
class H5ColumnLoader : public ColumnLoader {
 public:
  H5ColumnLoader(hid_t file, std::string path, hsize_t n, hsize_t file_bytes)
      : file_(file), path_(std::move(path)), n_(n), file_bytes_(file_bytes) {}
  ~H5ColumnLoader() override {
    std::lock_guard<std::mutex> lock(hdf5_mutex());
    H5Fclose(file_);
    if (mapping_ != MAP_FAILED) ::munmap(mapping_, static_cast<size_t>(file_bytes_));
  }
  /// The file's samples are out of time order: row k of a column is stored at order[k] (set
  /// before any column is read; such columns are read and reordered, never mapped).
  void set_order(std::vector<size_t> order) { order_ = std::move(order); }

  // A dataset stored plainly (contiguous, native float64, no filter, no external file) is used
  // where it lies in the file, mapped read-only: no copy, and only the pages a job touches are
  // read. Its first and last values are checked against the library's own read of them.
  const double* map(const std::string& name) const override {
    if (!order_.empty() || n_ == 0) return nullptr;
    std::lock_guard<std::mutex> lock(hdf5_mutex());
    H5Handle ds(H5Dopen2(file_, name.c_str(), H5P_DEFAULT), H5Dclose);
    if (ds.id < 0) return nullptr;  // load() says why
    H5Handle type(H5Dget_type(ds.id), H5Tclose);
    H5Handle create(H5Dget_create_plist(ds.id), H5Pclose);
    if (type.id < 0 || create.id < 0 || H5Tequal(type.id, H5T_NATIVE_DOUBLE) <= 0 ||
        H5Pget_layout(create.id) != H5D_CONTIGUOUS || H5Pget_nfilters(create.id) != 0 ||
        H5Pget_external_count(create.id) != 0) {
      return nullptr;
    }
    const haddr_t offset = H5Dget_offset(ds.id);
    const hsize_t bytes = n_ * sizeof(double);
    if (offset == HADDR_UNDEF || H5Dget_storage_size(ds.id) != bytes ||
        offset % alignof(double) != 0) {
      return nullptr;
    }
    if (offset > file_bytes_ || bytes > file_bytes_ - offset) {
      throw Error(path_ + ": field '" + name + "' is stored beyond the end of the file (" +
                  std::to_string(file_bytes_) + " bytes): the file is truncated or corrupt");
    }
    if (mapping_ == MAP_FAILED && !map_failed_) {
      const int fd = ::open(path_.c_str(), O_RDONLY | O_CLOEXEC);
      if (fd >= 0) {
        mapping_ = ::mmap(nullptr, static_cast<size_t>(file_bytes_), PROT_READ, MAP_PRIVATE, fd, 0);
        ::close(fd);
      }
      map_failed_ = mapping_ == MAP_FAILED;
    }
    if (mapping_ == MAP_FAILED) return nullptr;
    const double* values =
        reinterpret_cast<const double*>(static_cast<const char*>(mapping_) + offset);
    double ends[2];
    read_rows(name, 0, 1, &ends[0]);
    read_rows(name, n_ - 1, 1, &ends[1]);
    if (std::memcmp(&ends[0], values, sizeof(double)) != 0 ||
        std::memcmp(&ends[1], values + (n_ - 1), sizeof(double)) != 0) {
      return nullptr;
    }
    return values;
  }
  Eigen::VectorXd load(const std::string& name) const override {
    Eigen::VectorXd v(static_cast<Eigen::Index>(n_));
    if (order_.empty()) {  // in time order: straight into the column
      std::lock_guard<std::mutex> lock(hdf5_mutex());
      read_rows(name, 0, n_, v.data());
      return v;
    }
    Dataset d;
    d.name = name;
    {
      std::lock_guard<std::mutex> lock(hdf5_mutex());
      read_values(file_, path_, d, n_, file_bytes_);
    }
    for (size_t k = 0; k < n_; ++k) {
      v[static_cast<Eigen::Index>(k)] = d.values[static_cast<Eigen::Index>(order_[k])];
    }
    return v;
  }
  bool reads_rows() const override { return order_.empty(); }
  Eigen::VectorXd load_rows(const std::string& name, Eigen::Index first,
                            Eigen::Index count) const override {
    if (!order_.empty()) return load(name).segment(first, count);
    Eigen::VectorXd v(count);
    std::lock_guard<std::mutex> lock(hdf5_mutex());
    read_rows(name, static_cast<hsize_t>(first), static_cast<hsize_t>(count), v.data());
    return v;
  }

 private:
  // Rows [first, first + count) of a 1-D dataset of n_ values (a hyperslab), under the caller's
  // hold of the HDF5 lock.
  void read_rows(const std::string& name, hsize_t first, hsize_t count, double* out) const {
    H5Handle ds(H5Dopen2(file_, name.c_str(), H5P_DEFAULT), H5Dclose);
    if (ds.id < 0) throw Error(path_ + ": field '" + name + "' cannot be opened (corrupt object)");
    const std::string problem = h5_stored_values_problem(ds.id, n_, file_bytes_);
    if (!problem.empty()) throw Error(path_ + ": field '" + name + "' " + problem);
    if (count == 0) return;
    H5Handle file_space(H5Dget_space(ds.id), H5Sclose);
    H5Handle memory_space(H5Screate_simple(1, &count, nullptr), H5Sclose);
    if (file_space.id < 0 || memory_space.id < 0 ||
        H5Sselect_hyperslab(file_space.id, H5S_SELECT_SET, &first, nullptr, &count, nullptr) < 0 ||
        H5Dread(ds.id, H5T_NATIVE_DOUBLE, memory_space.id, file_space.id, H5P_DEFAULT, out) < 0) {
      throw Error(path_ + ": field '" + name + "' cannot be read as float64 (corrupt data)");
    }
  }

  hid_t file_;
  std::string path_;
  std::vector<size_t> order_;  // empty: already in time order
  hsize_t n_, file_bytes_;
  mutable void* mapping_ = MAP_FAILED;  // the whole file, read-only, once a column is mapped
  mutable bool map_failed_ = false;
};

hsize_t element_count(const Dataset& d) {
  hsize_t c = 1;
  for (hsize_t x : d.dims) c *= x;
  return c;
}

}  // namespace

namespace {

// The file's series: every dataset of numbers with more than one sample, as 1-D datasets.
// Groups, named types, datasets of other types and scalars are left out with a note
// (`N` and `dt` silently: they are derived from tt).
std::vector<Dataset> series_of(hid_t file_id, const std::string& path,
                               const std::vector<std::string>& names, FlightData* data) {
  std::vector<Dataset> series;
  for (const std::string& name : names) {
    H5O_info_t info;
    if (H5Oget_info_by_name2(file_id, name.c_str(), &info, H5O_INFO_BASIC, H5P_DEFAULT) < 0) {
      throw Error(path + ": field '" + name + "' cannot be read (corrupt object header)");
    }
    if (info.type != H5O_TYPE_DATASET) {
      data->add_read_note(path + ": '" + name + "' is a " +
                          (info.type == H5O_TYPE_GROUP ? "group" : "named type") +
                          ", not a dataset of the flight schema; left out");
      continue;
    }
    std::string why;
    Dataset d = open_dataset(file_id, path, name, &why);
    if (!d.numeric) {
      data->add_read_note(path + ": field '" + name + "' is a " + why +
                          " dataset; the flight schema holds numbers only; left out");
      continue;
    }
    const bool scalar =
        d.dims.empty() || (d.dims.size() == 1 && d.dims[0] == 1 && (name == "N" || name == "dt"));
    if (scalar) {  // `N`, `dt`: derived from tt instead (dt is wrong in some files)
      if (name != "N" && name != "dt") {
        data->add_read_note(path + ": field '" + name + "' is a scalar, not a series; left out");
      }
      continue;
    }
    if (d.dims.size() != 1) {
      if (d.dims.size() == 2 && (d.dims[0] == 1 || d.dims[1] == 1)) {
        d.dims = {d.dims[0] * d.dims[1]};
      } else {
        throw Error(path + ": field '" + name + "' has rank " + std::to_string(d.dims.size()) +
                    ", expected a 1-D dataset");
      }
    }
    series.push_back(std::move(d));
  }

  return series;
}

// A time base with a NaN or Inf cannot place its samples: refused, naming the first. Returns
// whether tt is in time order (one pass for both).
bool require_finite_tt(const std::string& path, const Eigen::Ref<const Eigen::VectorXd>& t) {
  bool finite = true, sorted = true;
  for (Eigen::Index k = 0; k < t.size(); ++k) {
    finite &= std::isfinite(t[k]);
    if (k > 0) sorted &= !(t[k] < t[k - 1]);
  }
  if (finite) return sorted;
  Eigen::Index bad = 0, first = t.size();
  for (Eigen::Index k = 0; k < t.size(); ++k) {
    if (!std::isfinite(t[k])) {
      if (!bad++) first = k;
    }
  }
  throw Error(path + ": field 'tt' has " + std::to_string(bad) + " non-finite value(s) (" +
              (std::isnan(t[first]) ? "NaN" : "Inf") + " at sample " + std::to_string(first) +
              "); samples without a time cannot be placed");
}

// Every series but tt declared to `data`, read on first use through `loader`; of two
// generations of a name, the final one.
void declare_lazy_columns(const std::vector<Dataset>& series, const std::string& path,
                          const std::shared_ptr<H5ColumnLoader>& loader, FlightData* data) {
  for (const Dataset& d : series) {
    if (d.name == "tt") continue;
    const std::string canonical = FlightData::canonical_name(d.name);
    // When both generations are present, the final name wins.
    if (canonical != d.name && std::any_of(series.begin(), series.end(),
                                           [&](const Dataset& e) { return e.name == canonical; })) {
      data->add_read_note(path + ": field '" + d.name + "' is the older name of '" + canonical +
                          "', which the file also holds; '" + canonical + "' is used");
      continue;
    }
    data->set_lazy(canonical, d.name, loader);
  }
}

}  // namespace

FlightData read_flight_h5(const std::string& path) {
  H5Eset_auto2(H5E_DEFAULT, nullptr, nullptr);
  hsize_t file_bytes = 0;
  require_regular_file(path, "flight file");
  {
    std::ifstream probe(path, std::ios::binary | std::ios::ate);
    if (!probe.good()) throw Error(path + ": file not found or not readable");
    file_bytes = static_cast<hsize_t>(std::max<std::streamoff>(probe.tellg(), 0));
  }
  if (H5Fis_hdf5(path.c_str()) <= 0) throw Error(path + ": not an HDF5 file");
  const std::string crash = probe_h5_structure(path);
  if (!crash.empty()) {
    throw Error(path + ": corrupt HDF5 file: the HDF5 library fails on its structure (" + crash +
                " in a probe process)");
  }
  H5Handle file(H5Fopen(path.c_str(), H5F_ACC_RDONLY, H5P_DEFAULT), H5Fclose);
  if (file.id < 0) throw Error(path + ": cannot open HDF5 file (corrupt superblock)");

  std::vector<std::string> names;
  if (H5Literate(file.id, H5_INDEX_NAME, H5_ITER_NATIVE, nullptr, append_h5_link_name, &names) <
      0) {
    throw Error(path + ": cannot list the fields (corrupt root group)");
  }
  FlightData data;
  data.set_source(path);
  std::vector<Dataset> series = series_of(file.id, path, names, &data);

  auto tt_it =
      std::find_if(series.begin(), series.end(), [](const Dataset& d) { return d.name == "tt"; });
  if (tt_it == series.end()) throw Error(path + ": field 'tt' not found");
  const hsize_t n_declared = element_count(*tt_it);
  if (n_declared == 0) throw Error(path + ": field 'tt' is empty");
  // Every series must have tt's length: checked on the declared shapes, before any allocation.
  for (const Dataset& d : series) {
    if (element_count(d) != n_declared) {
      throw Error(path + ": field '" + d.name + "' has " + std::to_string(element_count(d)) +
                  " samples, 'tt' has " + std::to_string(n_declared));
    }
  }
  // tt in place when the file allows (else read), checked, and the samples put in time order
  // (stable), as DATA.md prescribes; every other column on first use (a command reads only what
  // it touches).
  const hid_t file_id = file.id;
  file.id = -1;  // the loader owns the open file now
  auto loader = std::make_shared<H5ColumnLoader>(file_id, path, n_declared, file_bytes);
  const double* tt_in_place = loader->map("tt");
  if (!tt_in_place) read_values(file_id, path, *tt_it, n_declared, file_bytes);
  const Eigen::Map<const Eigen::VectorXd> t(tt_in_place ? tt_in_place : tt_it->values.data(),
                                            static_cast<Eigen::Index>(n_declared));
  const size_t n = static_cast<size_t>(n_declared);
  if (require_finite_tt(path, t)) {
    if (tt_in_place) {
      data.set_lazy("tt", "tt", loader, t.size());
    } else {
      data.set("tt", std::move(tt_it->values));
    }
  } else {
    std::vector<size_t> order(n);
    std::iota(order.begin(), order.end(), 0);
    std::stable_sort(order.begin(), order.end(), [&](size_t a, size_t b) {
      return t[static_cast<Eigen::Index>(a)] < t[static_cast<Eigen::Index>(b)];
    });
    data.add_read_note(path + ": field 'tt' was not in time order; the samples were sorted by tt");
    Eigen::VectorXd v(static_cast<Eigen::Index>(n));
    for (size_t k = 0; k < n; ++k) {
      v[static_cast<Eigen::Index>(k)] = t[static_cast<Eigen::Index>(order[k])];
    }
    data.set("tt", std::move(v));
    loader->set_order(std::move(order));
  }
  declare_lazy_columns(series, path, loader, &data);
  if (n > 1) {
    const double dt = data.dt_s();
    if (!(dt >= 1e-6)) {
      throw Error(path + ": field 'tt' steps by " + std::to_string(dt) +
                  " s (median): below 1 microsecond, not a flight's sample period");
    }
  }
  return data;
}

FlightH5Writer::FlightH5Writer(std::string path, std::vector<std::string> names,
                               Eigen::Index samples, const std::vector<std::string>& inputs)
    : path_(std::move(path)), names_(std::move(names)), inputs_(inputs), samples_(samples) {
  H5Eset_auto2(H5E_DEFAULT, nullptr, nullptr);
  check_output_path(path_, inputs_);
  tmp_ = temporary_path(path_);
  file_ = H5Fcreate(tmp_.c_str(), H5F_ACC_TRUNC, H5P_DEFAULT, H5P_DEFAULT);
  if (file_ < 0) throw Error(path_ + ": cannot create file");
  datasets_.reserve(names_.size());
  const hsize_t n = static_cast<hsize_t>(std::max<Eigen::Index>(samples_, 0));
  for (const std::string& name : names_) {
    H5Handle space(H5Screate_simple(1, &n, nullptr), H5Sclose);
    const hid_t ds = H5Dcreate2(file_, name.c_str(), H5T_IEEE_F64LE, space.id, H5P_DEFAULT,
                                H5P_DEFAULT, H5P_DEFAULT);
    if (ds < 0) {
      discard();
      throw Error(path_ + ": cannot write field '" + name + "'");
    }
    datasets_.push_back(ds);
  }
}

FlightH5Writer::~FlightH5Writer() { discard(); }

void FlightH5Writer::discard() {
  for (int64_t ds : datasets_) {
    if (ds >= 0) H5Dclose(ds);
  }
  datasets_.clear();
  if (file_ >= 0) {
    H5Fclose(file_);
    file_ = -1;
    std::remove(tmp_.c_str());
  }
}

void FlightH5Writer::write_rows(size_t column, Eigen::Index first, Eigen::Index count,
                                const double* values) {
  if (column >= datasets_.size() || first < 0 || count < 0 || first + count > samples_) {
    throw Error(path_ + ": rows [" + std::to_string(first) + ", " + std::to_string(first + count) +
                ") of column " + std::to_string(column) + " outside the file");
  }
  if (count == 0) return;
  const hsize_t start = static_cast<hsize_t>(first), n = static_cast<hsize_t>(count);
  H5Handle file_space(H5Dget_space(datasets_[column]), H5Sclose);
  H5Handle memory_space(H5Screate_simple(1, &n, nullptr), H5Sclose);
  if (file_space.id < 0 || memory_space.id < 0 ||
      H5Sselect_hyperslab(file_space.id, H5S_SELECT_SET, &start, nullptr, &n, nullptr) < 0 ||
      H5Dwrite(datasets_[column], H5T_NATIVE_DOUBLE, memory_space.id, file_space.id, H5P_DEFAULT,
               values) < 0) {
    throw Error(path_ + ": cannot write field '" + names_[column] + "'");
  }
}

void FlightH5Writer::finish(double dt_s) {
  auto scalar = [&](const char* name, double value) {
    H5Handle space(H5Screate(H5S_SCALAR), H5Sclose);
    H5Handle ds(
        H5Dcreate2(file_, name, H5T_IEEE_F64LE, space.id, H5P_DEFAULT, H5P_DEFAULT, H5P_DEFAULT),
        H5Dclose);
    if (ds.id < 0 ||
        H5Dwrite(ds.id, H5T_NATIVE_DOUBLE, H5S_ALL, H5S_ALL, H5P_DEFAULT, &value) < 0) {
      throw Error(path_ + ": cannot write field '" + name + "'");
    }
  };
  scalar("N", static_cast<double>(samples_));
  scalar("dt", dt_s);
  for (int64_t& ds : datasets_) {
    const hid_t id = ds;
    ds = -1;
    if (H5Dclose(id) < 0) {
      discard();
      throw Error(path_ + ": write failed (close)");
    }
  }
  datasets_.clear();
  if (H5Fflush(file_, H5F_SCOPE_GLOBAL) < 0) {
    discard();
    throw Error(path_ + ": write failed (flush)");
  }
  const hid_t id = file_;
  file_ = -1;
  if (H5Fclose(id) < 0) {
    std::remove(tmp_.c_str());
    throw Error(path_ + ": write failed (close)");
  }
  commit_temporary(tmp_, path_, inputs_);
}

void write_flight_h5(const FlightData& data, const std::string& path,
                     const std::vector<std::string>& inputs) {
  std::vector<std::string> names;
  for (const std::string& name : data.names()) {
    if (name != "N" && name != "dt") names.push_back(name);
  }
  const Eigen::Index n = std::max<Eigen::Index>(data.size(), 0);
  FlightH5Writer writer(path, names, n, inputs);
  for (size_t c = 0; c < names.size(); ++c)
    writer.write_rows(c, 0, n, data.column(names[c]).data());
  writer.finish(n > 1 ? data.dt_s() : 0.1);
}

}  // namespace magcomp
