// magcomp: the main field along a recorded flight (igrf_track.h).
#include "magcomp/core/geo/igrf_track.h"

#include <cmath>

namespace magcomp {

Eigen::VectorXd igrf_total_nT(const FlightData& data, const Igrf& igrf) {
  const Eigen::Index n = data.size();
  const auto lat = data.column("lat");
  const auto lon = data.column("lon");
  const auto h = data.column("utm_z");
  const auto year = data.column("year");
  const auto doy = data.column("doy");
  const auto tt = data.tt();
  Eigen::VectorXd out(n);
  for (Eigen::Index i = 0; i < n; ++i) {
    if (!std::isfinite(lat[i]) || !std::isfinite(lon[i]) || !std::isfinite(h[i]) ||
        !std::isfinite(year[i]) || !std::isfinite(doy[i])) {
      out[i] = NAN;
      continue;
    }
    const double y = decimal_year(static_cast<int>(year[i]), doy[i], tt[i]);
    out[i] = igrf.geodetic(lat[i], lon[i], h[i], y).total_nT();
  }
  return out;
}

}  // namespace magcomp
