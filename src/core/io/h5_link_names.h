// magcomp: the names of a group's links, collected by H5Literate (the flight reader and its probe).
#pragma once

#include <hdf5.h>

#include <string>
#include <vector>

namespace magcomp {

/// H5Literate callback: appends each link's name to the std::vector<std::string> at `out`.
inline herr_t append_h5_link_name(hid_t, const char* name, const H5L_info_t*, void* out) {
  static_cast<std::vector<std::string>*>(out)->emplace_back(name);
  return 0;
}

}  // namespace magcomp
