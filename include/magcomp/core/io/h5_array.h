// magcomp: one named float64 array of an HDF5 file (any rank), for the files that are not flights
// (anomaly maps, reference vectors).
#pragma once

#include <string>
#include <utility>
#include <vector>

namespace magcomp {

/// An array as stored: its dimensions (slowest first, as HDF5 gives them) and its values in that
/// row-major order. A scalar dataset has no dimensions and one value.
struct H5Array {
  std::vector<size_t> dims;
  std::vector<double> values;
  /// Element [i][j] of a 2-D array, [i][j][k] of a 3-D one (row-major).
  double at(size_t i, size_t j) const { return values[i * dims.at(1) + j]; }
  double at(size_t i, size_t j, size_t k) const {
    return values[(i * dims.at(1) + j) * dims.at(2) + k];
  }
};

/// Reads dataset `name` (e.g. "map" or "ekf/P0") of `path` as float64. Throws magcomp::Error
/// naming the file and dataset when either is missing or unreadable.
H5Array read_h5_array(const std::string& path, const std::string& name);

/// Writes the arrays (name -> array, top-level datasets) as a new HDF5 file, atomically (a
/// temporary file renamed; never over one of `inputs`). Throws magcomp::Error naming the file.
void write_h5_arrays(const std::string& path,
                     const std::vector<std::pair<std::string, H5Array>>& arrays,
                     const std::vector<std::string>& inputs = {});

/// Whether `path` holds a dataset `name` (false for a missing file too).
bool h5_has(const std::string& path, const std::string& name);

}  // namespace magcomp
