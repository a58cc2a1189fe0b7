// MagNav.jl's simple navigation example (test/data/reference/magnav_nav): its flight's columns.
#pragma once

#include <Eigen/Core>
#include <string>

#include "magcomp/core/io/h5_array.h"
#include "test_util.h"

namespace magcomp::test {

/// Column `name` of simple_xyz.h5 (MagNav.jl's units: degrees, metres, seconds, nT).
inline Eigen::VectorXd simple_example_column(const std::string& name) {
  const H5Array a = read_h5_array(reference_dir() + "/magnav_nav/simple_xyz.h5", name);
  return Eigen::Map<const Eigen::VectorXd>(a.values.data(),
                                           static_cast<Eigen::Index>(a.values.size()));
}

}  // namespace magcomp::test
