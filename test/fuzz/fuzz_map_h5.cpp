// libFuzzer target: the anomaly map reader (MagNav.jl's HDF5 layout) on arbitrary bytes, then
// the map used as the filter uses it: values, gradients and coverage on and off the grid, and an
// upward continuation. Anything but a clean magcomp::Error (or a map whose every value read is
// finite) is a finding.
#include <unistd.h>

#include <cmath>
#include <cstdint>
#include <cstdio>
#include <cstdlib>
#include <string>

#include "magcomp/core/error.h"
#include "magcomp/core/nav/anomaly_map.h"

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  static const std::string path = "/tmp/magcomp_fuzz_map_" + std::to_string(::getpid()) + ".h5";
  FILE* f = std::fopen(path.c_str(), "wb");
  if (!f) return 0;
  std::fwrite(data, 1, size, f);
  std::fclose(f);
  try {
    magcomp::nav::AnomalyMap m = magcomp::nav::read_anomaly_map(path);
    const Eigen::Index ny = m.lat_rad.size(), nx = m.lon_rad.size();
    for (int interp = 0; interp < 2; ++interp) {
      m.interpolation = interp ? magcomp::nav::AnomalyMap::Interpolation::Cubic
                               : magcomp::nav::AnomalyMap::Interpolation::Linear;
      for (double u : {-0.5, 0.0, 0.37, 0.5, 1.0, 1.5}) {
        const double lat = m.lat_rad[0] + u * (m.lat_rad[ny - 1] - m.lat_rad[0]);
        const double lon = m.lon_rad[0] + u * (m.lon_rad[nx - 1] - m.lon_rad[0]);
        const double v = m.value(lat, lon);
        const Eigen::Vector2d g = m.gradient(lat, lon);
        (void)m.covers(lat, lon);
        if (!std::isfinite(v) || !g.allFinite()) std::abort();  // a value the filter would use
      }
    }
    if (ny * nx <= 4096) (void)magcomp::nav::continued_to(m, m.alt_m + 100.0);
  } catch (const magcomp::Error&) {
  }
  return 0;
}
