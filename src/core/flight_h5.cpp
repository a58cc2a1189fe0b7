// magcomp: MIT challenge HDF5 flight files, read and write (HDF5 C API).
#include <hdf5.h>
#include <unistd.h>

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <fstream>
#include <numeric>

#include "magcomp/core/error.h"
#include "magcomp/core/flight_data.h"

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

herr_t collect_name(hid_t, const char* name, const H5L_info_t*, void* out) {
  static_cast<std::vector<std::string>*>(out)->emplace_back(name);
  return 0;
}

struct Dataset {
  std::string name;
  std::vector<hsize_t> dims;
  std::vector<double> values;
  bool numeric = true;
};

Dataset read_dataset(hid_t file, const std::string& path, const std::string& name) {
  Dataset d;
  d.name = name;
  H5Handle ds(H5Dopen2(file, name.c_str(), H5P_DEFAULT), H5Dclose);
  if (ds.id < 0) throw Error(path + ": field '" + name + "' cannot be opened");
  H5Handle type(H5Dget_type(ds.id), H5Tclose);
  const H5T_class_t cls = H5Tget_class(type.id);
  if (cls != H5T_FLOAT && cls != H5T_INTEGER) {
    d.numeric = false;
    return d;
  }
  H5Handle space(H5Dget_space(ds.id), H5Sclose);
  const int rank = H5Sget_simple_extent_ndims(space.id);
  d.dims.resize(static_cast<size_t>(std::max(rank, 0)));
  if (rank > 0) H5Sget_simple_extent_dims(space.id, d.dims.data(), nullptr);
  const hssize_t count = H5Sget_simple_extent_npoints(space.id);
  d.values.resize(static_cast<size_t>(std::max<hssize_t>(count, 0)));
  if (count > 0 &&
      H5Dread(ds.id, H5T_NATIVE_DOUBLE, H5S_ALL, H5S_ALL, H5P_DEFAULT, d.values.data()) < 0) {
    throw Error(path + ": field '" + name + "' cannot be read as float64");
  }
  return d;
}

}  // namespace

FlightData read_flight_h5(const std::string& path) {
  H5Eset_auto2(H5E_DEFAULT, nullptr, nullptr);
  {
    std::ifstream probe(path);
    if (!probe.good()) throw Error(path + ": file not found or not readable");
  }
  if (H5Fis_hdf5(path.c_str()) <= 0) throw Error(path + ": not an HDF5 file");
  H5Handle file(H5Fopen(path.c_str(), H5F_ACC_RDONLY, H5P_DEFAULT), H5Fclose);
  if (file.id < 0) throw Error(path + ": cannot open HDF5 file");

  std::vector<std::string> names;
  H5Literate(file.id, H5_INDEX_NAME, H5_ITER_NATIVE, nullptr, collect_name, &names);

  std::vector<Dataset> series;
  for (const std::string& name : names) {
    H5O_info_t info;
    if (H5Oget_info_by_name2(file.id, name.c_str(), &info, H5O_INFO_BASIC, H5P_DEFAULT) < 0 ||
        info.type != H5O_TYPE_DATASET) {
      continue;  // groups and other objects are not part of the schema
    }
    Dataset d = read_dataset(file.id, path, name);
    if (!d.numeric) continue;
    const bool scalar =
        d.dims.empty() || (d.dims.size() == 1 && d.dims[0] == 1 && (name == "N" || name == "dt"));
    if (scalar) continue;  // `N`, `dt`: derived from tt instead (dt is wrong in some files)
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

  auto tt_it =
      std::find_if(series.begin(), series.end(), [](const Dataset& d) { return d.name == "tt"; });
  if (tt_it == series.end()) throw Error(path + ": field 'tt' not found");
  const size_t n = tt_it->values.size();
  if (n == 0) throw Error(path + ": field 'tt' is empty");

  // Sort by tt (stable, NaN last), as DATA.md prescribes.
  std::vector<size_t> order(n);
  std::iota(order.begin(), order.end(), 0);
  const std::vector<double>& t = tt_it->values;
  const bool sorted = std::is_sorted(t.begin(), t.end());
  if (!sorted) {
    std::stable_sort(order.begin(), order.end(), [&](size_t a, size_t b) {
      if (std::isnan(t[a])) return false;
      if (std::isnan(t[b])) return true;
      return t[a] < t[b];
    });
  }

  FlightData data;
  data.set_source(path);
  auto add = [&](const Dataset& d) {
    if (d.values.size() != n) {
      throw Error(path + ": field '" + d.name + "' has " + std::to_string(d.values.size()) +
                  " samples, 'tt' has " + std::to_string(n));
    }
    Eigen::VectorXd v(static_cast<Eigen::Index>(n));
    for (size_t k = 0; k < n; ++k) v[static_cast<Eigen::Index>(k)] = d.values[order[k]];
    const std::string canonical = FlightData::canonical_name(d.name);
    // When both generations are present, the final name wins.
    if (canonical != d.name && data.has(canonical)) return;
    data.set(canonical, std::move(v));
  };
  add(*tt_it);
  for (const Dataset& d : series) {
    if (d.name != "tt") add(d);
  }
  return data;
}

void write_flight_h5(const FlightData& data, const std::string& path) {
  H5Eset_auto2(H5E_DEFAULT, nullptr, nullptr);
  const std::string tmp = path + ".tmp." + std::to_string(::getpid());
  {
    H5Handle file(H5Fcreate(tmp.c_str(), H5F_ACC_TRUNC, H5P_DEFAULT, H5P_DEFAULT), H5Fclose);
    if (file.id < 0) throw Error(path + ": cannot create file");
    auto write = [&](const std::string& name, const double* values, hsize_t n, bool scalar) {
      H5Handle space(scalar ? H5Screate(H5S_SCALAR) : H5Screate_simple(1, &n, nullptr), H5Sclose);
      H5Handle ds(H5Dcreate2(file.id, name.c_str(), H5T_IEEE_F64LE, space.id, H5P_DEFAULT,
                             H5P_DEFAULT, H5P_DEFAULT),
                  H5Dclose);
      if (ds.id < 0 ||
          H5Dwrite(ds.id, H5T_NATIVE_DOUBLE, H5S_ALL, H5S_ALL, H5P_DEFAULT, values) < 0) {
        throw Error(path + ": cannot write field '" + name + "'");
      }
    };
    try {
      const hsize_t n = static_cast<hsize_t>(std::max<Eigen::Index>(data.size(), 0));
      for (const std::string& name : data.names()) {
        if (name == "N" || name == "dt") continue;
        write(name, data.column(name).data(), n, false);
      }
      const double count = static_cast<double>(n);
      write("N", &count, 1, true);
      const double dt = n > 1 ? data.dt_s() : 0.1;
      write("dt", &dt, 1, true);
    } catch (...) {
      std::remove(tmp.c_str());
      throw;
    }
  }
  if (std::rename(tmp.c_str(), path.c_str()) != 0) {
    std::remove(tmp.c_str());
    throw Error(path + ": cannot rename temporary file into place");
  }
}

}  // namespace magcomp
