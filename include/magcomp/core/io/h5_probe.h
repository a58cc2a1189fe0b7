// magcomp: the HDF5 library trusts the sizes and addresses in a file's structure (B-trees, local
// heaps, object headers) and crashes on some corrupt files instead of returning an error. Every
// HDF5 reader therefore walks the structure first in a child process: if the child dies, the file
// is refused and the parent never calls the library on it.
#pragma once

#include <string>

namespace magcomp {

/// Walks the root group's datasets of `path` (open, type, shape, storage size) in a forked child,
/// and reads as numbers every dataset of at most `read_values` values whose declared size the
/// file can hold (a corrupt datatype crashes the library's conversion, not its structure walk).
/// Returns "" when the walk completed (or could not be forked), else what ended the child
/// ("signal 11"). MAGCOMP_HDF5_PROBE=0 turns the probe off (the fuzz targets do, to see the
/// library's own crashes).
std::string probe_h5_structure(const std::string& path, unsigned long long read_values = 0);

}  // namespace magcomp
