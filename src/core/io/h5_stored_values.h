// magcomp: whether the values a dataset declares can be data the file holds, checked before any
// allocation or read (the flight reader and the map reader).
#pragma once

#include <hdf5.h>

#include <string>

namespace magcomp {

/// Why the `count` values dataset `ds` declares cannot be real data of a file of `file_bytes`
/// bytes, or "" when they can. Refused: a number type of a size no number has (the library would
/// allocate count × that size to convert it), a plain (contiguous, compact or unfiltered chunked)
/// dataset storing fewer bytes than count × its type's size, and a filtered one storing under a
/// thousandth of the values (beyond any compression of float samples).
inline std::string h5_stored_values_problem(hid_t ds, hsize_t count, hsize_t file_bytes) {
  if (count == 0) return "";
  const hid_t type = H5Dget_type(ds);
  if (type < 0) return "has an unreadable type";
  const size_t type_bytes = H5Tget_size(type);
  const H5T_class_t cls = H5Tget_class(type);
  H5Tclose(type);
  if ((cls == H5T_FLOAT || cls == H5T_INTEGER) &&
      !(type_bytes == 1 || type_bytes == 2 || type_bytes == 4 || type_bytes == 8 ||
        type_bytes == 16)) {
    return "has a " + std::to_string(type_bytes) + "-byte number type (corrupt type)";
  }
  const hsize_t stored = H5Dget_storage_size(ds);
  const std::string declared = "declares " + std::to_string(count) + " values";
  if (stored == 0 || count > stored * 1000 || count > file_bytes * 1000)
    return declared + " but the file stores " + std::to_string(stored) + " bytes of it";
  const hid_t create = H5Dget_create_plist(ds);
  if (create < 0) return "";
  const H5D_layout_t layout = H5Pget_layout(create);
  const int filters = H5Pget_nfilters(create);
  const int external = H5Pget_external_count(create);
  H5Pclose(create);
  const bool plain = (layout == H5D_CONTIGUOUS || layout == H5D_COMPACT ||
                      (layout == H5D_CHUNKED && filters == 0)) &&
                     external <= 0;
  if (plain && type_bytes > 0 && count > stored / type_bytes) {
    return declared + " (" + std::to_string(count * type_bytes) + " bytes) but the file stores " +
           std::to_string(stored) + " bytes of it";
  }
  return "";
}

}  // namespace magcomp
