// magcomp: the main field along a recorded flight.
#pragma once

#include <Eigen/Core>

#include "magcomp/core/geo/igrf.h"
#include "magcomp/core/io/flight_data.h"

namespace magcomp {

/// The main field `igrf`'s total (nT) at each sample from lat, lon (deg), utm_z (height above the
/// ellipsoid, m), year, doy, tt; NaN where one of them is not finite. Throws magcomp::Error
/// naming the file and the missing field.
Eigen::VectorXd igrf_total_nT(const FlightData& data, const Igrf& igrf);

}  // namespace magcomp
