// magcomp: anomaly maps: bilinear interpolation, upward continuation, MagNav.jl's files.
#include "magcomp/core/nav/anomaly_map.h"

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <vector>

#include "magcomp/core/error.h"
#include "magcomp/core/geo/potential_field.h"
#include "magcomp/core/geo/wgs84.h"
#include "magcomp/core/io/file_io.h"
#include "magcomp/core/io/h5_array.h"
#include "magcomp/core/math/constants.h"

namespace magcomp::nav {
namespace {

constexpr double kGradientStep_rad = 1.0e-8f;  // MagNav.jl's map_grad step (a Float32 literal)
constexpr double kMaxMapAltitude_m = 1e5;      // a map's altitude, within 100 km of the ellipsoid
constexpr double kMinCell_rad = 1e-10;         // 0.6 mm on the ground: no anomaly map is finer

// Fractional index of x on a uniform axis from a[0] to a[n-1]: the cell and the weight in it.
void locate(const Eigen::VectorXd& a, double x, Eigen::Index* cell, double* t) {
  const Eigen::Index n = a.size();
  const double step = (a[n - 1] - a[0]) / static_cast<double>(n - 1);
  const double u = (x - a[0]) / step;
  // The cell is clamped in floating point first: a position far off the grid (or NaN) is never
  // cast out of an integer's range.
  const double c =
      std::isfinite(u) ? std::clamp(std::floor(u), 0.0, static_cast<double>(n - 2)) : 0.0;
  *cell = static_cast<Eigen::Index>(c);
  *t = u - c;
}

// A map axis: at least 2 finite values, increasing, uniform (each value within 5 % of a step of
// the line through the first and the last: a float32 axis passes, a stretched one does not).
Eigen::VectorXd axis(const H5Array& a, const std::string& path, const std::string& name) {
  if (a.dims.size() != 1 || a.values.size() < 2)
    throw Error(path + ": field '" + name + "' must be a vector of at least 2 values");
  Eigen::VectorXd v = Eigen::Map<const Eigen::VectorXd>(a.values.data(),
                                                        static_cast<Eigen::Index>(a.values.size()));
  for (Eigen::Index i = 0; i < v.size(); ++i)
    if (!std::isfinite(v[i]))
      throw Error(path + ": field '" + name + "' holds a non-finite value at index " +
                  std::to_string(i));
  for (Eigen::Index i = 1; i < v.size(); ++i)
    if (!(v[i] > v[i - 1])) throw Error(path + ": field '" + name + "' must increase");
  const Eigen::Index n = v.size();
  const double step = (v[n - 1] - v[0]) / static_cast<double>(n - 1);
  for (Eigen::Index i = 1; i + 1 < n; ++i) {
    const double off = std::abs(v[i] - (v[0] + step * static_cast<double>(i))) / step;
    if (off > 0.05) {
      char buf[64];
      std::snprintf(buf, sizeof buf, "%.3g", off);
      throw Error(path + ": field '" + name + "' is not uniform: value " + std::to_string(i) +
                  " lies " + buf + " steps off the regular grid (a map is a regular grid)");
    }
  }
  return v;
}

// Keys' cubic convolution kernel (a = -0.5) at distance x (in cells).
double keys(double x) {
  x = std::abs(x);
  if (x <= 1) return (1.5 * x - 2.5) * x * x + 1;
  if (x < 2) return ((-0.5 * x + 2.5) * x - 4) * x + 2;
  return 0.0;
}

// Cells that are not finite are masked; so is the whole map refused when no cell is left, or when a
// cell holds more than any magnetic anomaly. Masked cells take the valid cells' mean, so the
// interpolation and the FFT continuation stay finite; covers() keeps measurements off them.
void mask_invalid_cells(AnomalyMap* m, const std::string& path) {
  double sum = 0;
  long valid = 0;
  for (Eigen::Index i = 0; i < m->map_nT.rows(); ++i)
    for (Eigen::Index j = 0; j < m->map_nT.cols(); ++j) {
      const double v = m->map_nT(i, j);
      if (!std::isfinite(v)) m->mask(i, j) = 0.0;
      if (m->mask(i, j) == 0.0) continue;
      if (std::abs(v) > kMaxField_nT) {
        char buf[96];
        std::snprintf(buf, sizeof buf, "cell (%ld, %ld) holds %.6g nT", static_cast<long>(i),
                      static_cast<long>(j), v);
        throw Error(path + ": field 'map' " + buf +
                    ", beyond any magnetic field (|value| <= 1e6 nT)");
      }
      sum += v;
      ++valid;
    }
  if (valid == 0) throw Error(path + ": field 'map' has no valid cell (all masked or not finite)");
  const double mean = sum / static_cast<double>(valid);
  for (Eigen::Index i = 0; i < m->map_nT.rows(); ++i)
    for (Eigen::Index j = 0; j < m->map_nT.cols(); ++j)
      if (m->mask(i, j) == 0.0) m->map_nT(i, j) = mean;
}

}  // namespace

double AnomalyMap::value(double lat, double lon) const {
  Eigen::Index i, j;
  double t, s;
  locate(lat_rad, lat, &i, &t);
  locate(lon_rad, lon, &j, &s);
  if (interpolation == Interpolation::Cubic) {  // 4 x 4 cells, the edge rows repeated
    const Eigen::Index ny = map_nT.rows(), nx = map_nT.cols();
    double sum = 0;
    for (int a = -1; a <= 2; ++a) {
      const Eigen::Index r = std::clamp<Eigen::Index>(i + a, 0, ny - 1);
      const double wa = keys(t - a);
      double row = 0;
      for (int b = -1; b <= 2; ++b)
        row += keys(s - b) * map_nT(r, std::clamp<Eigen::Index>(j + b, 0, nx - 1));
      sum += wa * row;
    }
    return sum;
  }
  return (1 - t) * ((1 - s) * map_nT(i, j) + s * map_nT(i, j + 1)) +
         t * ((1 - s) * map_nT(i + 1, j) + s * map_nT(i + 1, j + 1));
}

Eigen::Vector2d AnomalyMap::gradient(double lat, double lon) const {
  const double d = kGradientStep_rad;
  return {(value(lat + d, lon) - value(lat - d, lon)) / 2 / d,
          (value(lat, lon + d) - value(lat, lon - d)) / 2 / d};
}

Eigen::Matrix2d AnomalyMap::curvature(double lat, double lon) const {
  const Eigen::Index ny = map_nT.rows(), nx = map_nT.cols();
  Eigen::Index i, j;
  double t, s;
  locate(lat_rad, lat, &i, &t);
  locate(lon_rad, lon, &j, &s);
  i += t > 0.5;  // the nearest node
  j += s > 0.5;
  if (ny < 3 || nx < 3 || i < 1 || j < 1 || i + 1 >= ny || j + 1 >= nx)
    return Eigen::Matrix2d::Zero();
  if (mask.size() != 0)
    for (int a = -1; a <= 1; ++a)
      for (int b = -1; b <= 1; ++b)
        if (mask(i + a, j + b) == 0) return Eigen::Matrix2d::Zero();
  const double dlat = (lat_rad[ny - 1] - lat_rad[0]) / double(ny - 1);
  const double dlon = (lon_rad[nx - 1] - lon_rad[0]) / double(nx - 1);
  const auto& m = map_nT;
  Eigen::Matrix2d c;
  c(0, 0) = (m(i + 1, j) - 2 * m(i, j) + m(i - 1, j)) / (dlat * dlat);
  c(1, 1) = (m(i, j + 1) - 2 * m(i, j) + m(i, j - 1)) / (dlon * dlon);
  c(0, 1) = c(1, 0) =
      (m(i + 1, j + 1) - m(i + 1, j - 1) - m(i - 1, j + 1) + m(i - 1, j - 1)) / (4 * dlat * dlon);
  return c;
}

double AnomalyMap::representation_var_nT2(double lat, double lon,
                                          const Eigen::Matrix2d& p_rad2) const {
  const Eigen::Matrix2d c = curvature(lat, lon);
  const Eigen::Matrix2d cp = c * p_rad2;
  double var = 0.5 * (cp * cp).trace();
  if (interpolation == Interpolation::Linear && lat_rad.size() > 1 && lon_rad.size() > 1) {
    Eigen::Index i, j;
    double t, s;
    locate(lat_rad, lat, &i, &t);
    locate(lon_rad, lon, &j, &s);
    t = std::clamp(t, 0.0, 1.0);
    s = std::clamp(s, 0.0, 1.0);
    const double dlat = (lat_rad[lat_rad.size() - 1] - lat_rad[0]) / double(lat_rad.size() - 1);
    const double dlon = (lon_rad[lon_rad.size() - 1] - lon_rad[0]) / double(lon_rad.size() - 1);
    const double e =
        0.5 * (t * (1 - t) * dlat * dlat * c(0, 0) + s * (1 - s) * dlon * dlon * c(1, 1));
    var += e * e;
  }
  return std::isfinite(var) ? var : 0.0;
}

bool AnomalyMap::covers(double lat, double lon) const {
  if (!(lat >= lat_rad[0] && lat <= lat_rad[lat_rad.size() - 1] && lon >= lon_rad[0] &&
        lon <= lon_rad[lon_rad.size() - 1]))
    return false;
  if (mask.size() == 0) return true;
  // Every cell the interpolation reads must be valid: the cell's 4 corners (bilinear) or the
  // 4 x 4 about it (cubic, the edge rows repeated).
  Eigen::Index i, j;
  double t, s;
  locate(lat_rad, lat, &i, &t);
  locate(lon_rad, lon, &j, &s);
  const int lo = interpolation == Interpolation::Cubic ? -1 : 0;
  const int hi = interpolation == Interpolation::Cubic ? 2 : 1;
  const Eigen::Index ny = mask.rows(), nx = mask.cols();
  for (int a = lo; a <= hi; ++a)
    for (int b = lo; b <= hi; ++b)
      if (mask(std::clamp<Eigen::Index>(i + a, 0, ny - 1),
               std::clamp<Eigen::Index>(j + b, 0, nx - 1)) == 0)
        return false;
  return true;
}

bool AnomalyMap::covered_value(double lat, double lon, double* v) const {
  if (interpolation == Interpolation::Cubic || mask.size() == 0) {
    if (!covers(lat, lon)) return false;
    *v = value(lat, lon);
    return true;
  }
  if (!(lat >= lat_rad[0] && lat <= lat_rad[lat_rad.size() - 1] && lon >= lon_rad[0] &&
        lon <= lon_rad[lon_rad.size() - 1]))
    return false;
  Eigen::Index i, j;
  double t, s;
  locate(lat_rad, lat, &i, &t);
  locate(lon_rad, lon, &j, &s);
  if (mask(i, j) == 0 || mask(i + 1, j) == 0 || mask(i, j + 1) == 0 || mask(i + 1, j + 1) == 0)
    return false;
  *v = (1 - t) * ((1 - s) * map_nT(i, j) + s * map_nT(i, j + 1)) +
       t * ((1 - s) * map_nT(i + 1, j) + s * map_nT(i + 1, j + 1));
  return true;
}

Eigen::Vector2d AnomalyMap::step_m() const {
  // Radii of curvature of the ellipsoid at the mean latitude (meridian and prime vertical).
  const double lat = 0.5 * (lat_rad[0] + lat_rad[lat_rad.size() - 1]);
  const double e2 = kWgs84Eccentricity * kWgs84Eccentricity, s2 = std::sin(lat) * std::sin(lat);
  const double rn = kWgs84SemiMajor_m / std::sqrt(1 - e2 * s2);
  const double rm = kWgs84SemiMajor_m * (1 - e2) / std::pow(1 - e2 * s2, 1.5);
  const double dlon = (lon_rad[lon_rad.size() - 1] - lon_rad[0]) / (lon_rad.size() - 1);
  const double dlat = (lat_rad[lat_rad.size() - 1] - lat_rad[0]) / (lat_rad.size() - 1);
  return {dlon * (rn + alt_m) * std::cos(lat), dlat * (rm + alt_m)};
}

AnomalyMap continued_to(const AnomalyMap& map, double alt_m) {
  if (alt_m < map.alt_m)
    throw Error("upward continuation: target altitude " + std::to_string(alt_m) +
                " m is below the map's " + std::to_string(map.alt_m) + " m");
  AnomalyMap out = map;
  const Eigen::Vector2d d = map.step_m();
  out.map_nT = upward_continue(map.map_nT, d.x(), d.y(), alt_m - map.alt_m);
  out.alt_m = alt_m;
  return out;
}

AnomalyMap read_anomaly_map(const std::string& path) {
  require_regular_file(path, "map file");
  AnomalyMap m;
  const H5Array grid = read_h5_array(path, "map");
  if (grid.dims.size() != 2) throw Error(path + ": field 'map' must be a 2-D grid");
  m.lon_rad = axis(read_h5_array(path, "xx"), path, "xx");
  m.lat_rad = axis(read_h5_array(path, "yy"), path, "yy");
  // MagNav.jl writes its maps from Julia (column-major): an ny x nx map is stored with the
  // dimensions (nx, ny). A file whose dimensions are (ny, nx) and not square is read row-major.
  const auto ny = static_cast<size_t>(m.lat_rad.size()), nx = static_cast<size_t>(m.lon_rad.size());
  const bool julia = grid.dims[0] == nx && grid.dims[1] == ny;
  if (!julia && !(grid.dims[0] == ny && grid.dims[1] == nx))
    throw Error(path + ": field 'map' is " + std::to_string(grid.dims[0]) + " x " +
                std::to_string(grid.dims[1]) + ", but yy has " + std::to_string(ny) +
                " values and xx " + std::to_string(nx));
  if (m.lat_rad.cwiseAbs().maxCoeff() > kPi / 2 || m.lon_rad.cwiseAbs().maxCoeff() > kPi) {
    m.lat_rad *= kDegToRad;
    m.lon_rad *= kDegToRad;
  }
  if (m.lat_rad.cwiseAbs().maxCoeff() > kPi / 2)
    throw Error(path + ": field 'yy' holds " +
                std::to_string(m.lat_rad.cwiseAbs().maxCoeff() / kDegToRad) +
                ", not a latitude in degrees or radians (a map on projected axes, metres, is not "
                "read: give its axes in degrees)");
  if (m.lon_rad.cwiseAbs().maxCoeff() > 2 * kPi)
    throw Error(path + ": field 'xx' holds " +
                std::to_string(m.lon_rad.cwiseAbs().maxCoeff() / kDegToRad) +
                ", not a longitude in degrees or radians (a map on projected axes, metres, is not "
                "read: give its axes in degrees)");
  for (const auto& [axis, name] : {std::pair{&m.lat_rad, "yy"}, std::pair{&m.lon_rad, "xx"}}) {
    const double step =
        ((*axis)[axis->size() - 1] - (*axis)[0]) / static_cast<double>(axis->size() - 1);
    if (!(step >= kMinCell_rad)) {
      char buf[64];
      std::snprintf(buf, sizeof buf, "%.3g", step / kDegToRad);
      throw Error(path + ": field '" + name + "' steps by " + buf +
                  " deg, below a millimetre: not a map's grid");
    }
  }
  auto element = [&](const H5Array& a, size_t i, size_t j) {
    return julia ? a.at(j, i) : a.at(i, j);
  };
  m.map_nT.resize(m.lat_rad.size(), m.lon_rad.size());
  for (size_t i = 0; i < ny; ++i)
    for (size_t j = 0; j < nx; ++j)
      m.map_nT(static_cast<Eigen::Index>(i), static_cast<Eigen::Index>(j)) = element(grid, i, j);
  const H5Array alt = read_h5_array(path, "alt");
  if (alt.values.empty() || !std::isfinite(alt.values[0]) ||
      std::abs(alt.values[0]) > kMaxMapAltitude_m)
    throw Error(path + ": field 'alt' must hold the map's altitude (m, finite, within " +
                std::to_string(static_cast<long>(kMaxMapAltitude_m)) + " m of the ellipsoid)");
  m.alt_m = alt.values[0];
  m.mask = Eigen::MatrixXd::Ones(m.map_nT.rows(), m.map_nT.cols());
  if (h5_has(path, "mask")) {
    const H5Array mask = read_h5_array(path, "mask");
    if (mask.dims != grid.dims) throw Error(path + ": field 'mask' must have the map's shape");
    for (size_t i = 0; i < ny; ++i)
      for (size_t j = 0; j < nx; ++j) {
        const double v = element(mask, i, j);
        m.mask(static_cast<Eigen::Index>(i), static_cast<Eigen::Index>(j)) =
            std::isfinite(v) && v != 0 ? 1.0 : 0.0;
      }
  }
  mask_invalid_cells(&m, path);
  if (h5_has(path, "error_sigma_nT")) {
    const H5Array e = read_h5_array(path, "error_sigma_nT");
    if (e.values.size() != 1 || !(e.values[0] >= 0 && e.values[0] <= kMaxField_nT))
      throw Error(path + ": field 'error_sigma_nT' must hold the map's error, one number in nT");
    m.error_sigma_nT = e.values[0];
  }
  return m;
}

void write_anomaly_map(const AnomalyMap& map, const std::string& path,
                       const std::vector<std::string>& inputs) {
  const auto ny = static_cast<size_t>(map.map_nT.rows()),
             nx = static_cast<size_t>(map.map_nT.cols());
  auto julia_layout = [&](const Eigen::MatrixXd& m) {
    H5Array a{{nx, ny}, std::vector<double>(nx * ny)};
    for (size_t i = 0; i < ny; ++i)
      for (size_t j = 0; j < nx; ++j)
        a.values[j * ny + i] = m(static_cast<Eigen::Index>(i), static_cast<Eigen::Index>(j));
    return a;
  };
  auto degrees = [](const Eigen::VectorXd& v) {
    H5Array a{{static_cast<size_t>(v.size())}, {}};
    for (Eigen::Index i = 0; i < v.size(); ++i) a.values.push_back(v[i] / kDegToRad);
    return a;
  };
  const Eigen::MatrixXd mask =
      map.mask.size() ? map.mask : Eigen::MatrixXd::Ones(map.map_nT.rows(), map.map_nT.cols());
  write_h5_arrays(path,
                  {{"map", julia_layout(map.map_nT)},
                   {"xx", degrees(map.lon_rad)},
                   {"yy", degrees(map.lat_rad)},
                   {"alt", H5Array{{}, {map.alt_m}}},
                   {"mask", julia_layout(mask)}},
                  inputs);
}

}  // namespace magcomp::nav
