// magcomp: one named float64 array of an HDF5 file.
#include "magcomp/core/io/h5_array.h"

#include <hdf5.h>

#include <sys/stat.h>

#include <cstdio>
#include <mutex>

#include "h5_stored_values.h"
#include "magcomp/core/error.h"
#include "magcomp/core/io/file_io.h"
#include "magcomp/core/io/h5_probe.h"

namespace magcomp {
namespace {

// Closes an HDF5 identifier when it goes out of scope.
struct Handle {
  hid_t id;
  herr_t (*close)(hid_t);
  ~Handle() {
    if (id >= 0) close(id);
  }
};

// Files whose structure the probe walked without a crash, by identity, size and modification
// time: a map or a reference file read dataset by dataset is probed once.
struct ProbedFile {
  dev_t dev;
  ino_t ino;
  off_t size;
  long long mtime_ns;
  bool operator==(const ProbedFile& o) const {
    return dev == o.dev && ino == o.ino && size == o.size && mtime_ns == o.mtime_ns;
  }
};
ProbedFile identity(const struct stat& st) {
  return {st.st_dev, st.st_ino, st.st_size,
          static_cast<long long>(st.st_mtim.tv_sec) * 1000000000LL + st.st_mtim.tv_nsec};
}
std::mutex& probed_mutex() {
  static std::mutex m;
  return m;
}
std::vector<ProbedFile>& probed() {
  static std::vector<ProbedFile> v;
  return v;
}
bool probed_clean(const std::string&, const struct stat& st) {
  std::lock_guard<std::mutex> lock(probed_mutex());
  for (const ProbedFile& p : probed())
    if (p == identity(st)) return true;
  return false;
}
void remember_clean(const std::string&, const struct stat& st) {
  std::lock_guard<std::mutex> lock(probed_mutex());
  if (probed().size() > 64) probed().erase(probed().begin());
  probed().push_back(identity(st));
}

}  // namespace

void write_h5_arrays(const std::string& path,
                     const std::vector<std::pair<std::string, H5Array>>& arrays,
                     const std::vector<std::string>& inputs) {
  check_output_path(path, inputs);
  const std::string tmp = temporary_path(path);
  H5Eset_auto2(H5E_DEFAULT, nullptr, nullptr);
  try {
    Handle file{H5Fcreate(tmp.c_str(), H5F_ACC_TRUNC, H5P_DEFAULT, H5P_DEFAULT), H5Fclose};
    if (file.id < 0) throw Error(path + ": cannot create (" + tmp + ")");
    for (const auto& [name, a] : arrays) {
      std::vector<hsize_t> dims(a.dims.begin(), a.dims.end());
      Handle space{a.dims.empty()
                       ? H5Screate(H5S_SCALAR)
                       : H5Screate_simple(static_cast<int>(dims.size()), dims.data(), nullptr),
                   H5Sclose};
      Handle ds{H5Dcreate2(file.id, name.c_str(), H5T_IEEE_F64LE, space.id, H5P_DEFAULT,
                           H5P_DEFAULT, H5P_DEFAULT),
                H5Dclose};
      if (space.id < 0 || ds.id < 0 ||
          H5Dwrite(ds.id, H5T_NATIVE_DOUBLE, H5S_ALL, H5S_ALL, H5P_DEFAULT, a.values.data()) < 0)
        throw Error(path + ": cannot write dataset '" + name + "'");
    }
  } catch (...) {
    std::remove(tmp.c_str());  // nothing half-written is left
    throw;
  }
  commit_temporary(tmp, path, inputs);
}

bool h5_has(const std::string& path, const std::string& name) {
  require_regular_file(path, "HDF5 file");
  H5Eset_auto2(H5E_DEFAULT, nullptr, nullptr);  // errors are ours to report, in one line
  {
    const hid_t file = H5Fopen(path.c_str(), H5F_ACC_RDONLY, H5P_DEFAULT);
    if (file < 0) return false;
    Handle f{file, H5Fclose};
    const hid_t ds = H5Dopen2(file, name.c_str(), H5P_DEFAULT);
    if (ds < 0) return false;
    H5Dclose(ds);
    return true;
  }
}

H5Array read_h5_array(const std::string& path, const std::string& name) {
  H5Array out;
  require_regular_file(path, "HDF5 file");
  struct stat st {};
  if (::stat(path.c_str(), &st) != 0) throw Error(path + ": file not found or not readable");
  const auto file_bytes = static_cast<hsize_t>(st.st_size);
  H5Eset_auto2(H5E_DEFAULT, nullptr, nullptr);  // errors are ours to report, in one line
  if (H5Fis_hdf5(path.c_str()) <= 0) throw Error(path + ": not an HDF5 file");
  if (!probed_clean(path, st)) {
    // The structure, and the values of every array up to 16 M values (maps, tracks, reference
    // vectors: each is read whole here anyway).
    const std::string crash = probe_h5_structure(path, 1ULL << 24);
    if (!crash.empty())
      throw Error(path +
                  ": corrupt HDF5 file: the HDF5 library fails on its structure or values (" +
                  crash + " in a probe process)");
    remember_clean(path, st);
  }
  {
    Handle file{H5Fopen(path.c_str(), H5F_ACC_RDONLY, H5P_DEFAULT), H5Fclose};
    if (file.id < 0) throw Error(path + ": cannot open as HDF5");
    Handle ds{H5Dopen2(file.id, name.c_str(), H5P_DEFAULT), H5Dclose};
    if (ds.id < 0) throw Error(path + ": dataset '" + name + "' not found");
    Handle space{H5Dget_space(ds.id), H5Sclose};
    const int rank = space.id < 0 ? -1 : H5Sget_simple_extent_ndims(space.id);
    if (rank < 0 || rank > 8) throw Error(path + ": dataset '" + name + "' has no simple shape");
    std::vector<hsize_t> dims(static_cast<size_t>(rank));
    if (rank > 0) H5Sget_simple_extent_dims(space.id, dims.data(), nullptr);
    size_t n = 1;
    for (hsize_t d : dims) {
      out.dims.push_back(static_cast<size_t>(d));
      if (d > 0 && n > (size_t{1} << 31) / d)
        throw Error(path + ": dataset '" + name + "' is too large");
      n *= static_cast<size_t>(d);
    }
    if (n > (size_t{1} << 31)) throw Error(path + ": dataset '" + name + "' is too large");
    // The declared size against the bytes the file stores for it, before any allocation.
    const std::string problem = h5_stored_values_problem(ds.id, n, file_bytes);
    if (!problem.empty()) throw Error(path + ": dataset '" + name + "' " + problem);
    try {
      out.values.resize(n);
    } catch (const std::bad_alloc&) {
      throw Error(path + ": dataset '" + name + "': not enough memory for " + std::to_string(n) +
                  " values");
    }
    if (n > 0 &&
        H5Dread(ds.id, H5T_NATIVE_DOUBLE, H5S_ALL, H5S_ALL, H5P_DEFAULT, out.values.data()) < 0)
      throw Error(path + ": dataset '" + name + "' cannot be read as numbers");
  }
  return out;
}

}  // namespace magcomp
