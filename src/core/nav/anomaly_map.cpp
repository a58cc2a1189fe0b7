// magcomp: anomaly maps: bilinear interpolation, FFT upward continuation, MagNav.jl's files.
#include "magcomp/core/nav/anomaly_map.h"

#include <algorithm>
#include <cmath>
#include <complex>
#include <unsupported/Eigen/FFT>
#include <vector>

#include "magcomp/core/error.h"
#include "magcomp/core/io/h5_array.h"
#include "magcomp/core/math/constants.h"

namespace magcomp::nav {
namespace {

constexpr double kWgs84A_m = 6378137.0;        // MagNav.jl's r_earth
constexpr double kWgs84E = 0.0818191908426;    // first eccentricity
constexpr double kGradientStep_rad = 1.0e-8f;  // MagNav.jl's map_grad step (a Float32 literal)

// Fractional index of x on a uniform axis from a[0] to a[n-1]: the cell and the weight in it.
void locate(const Eigen::VectorXd& a, double x, Eigen::Index* cell, double* t) {
  const Eigen::Index n = a.size();
  const double step = (a[n - 1] - a[0]) / static_cast<double>(n - 1);
  const double u = (x - a[0]) / step;
  *cell = std::clamp<Eigen::Index>(static_cast<Eigen::Index>(std::floor(u)), 0, n - 2);
  *t = u - static_cast<double>(*cell);
}

// In-place 2-D FFT (forward or inverse, unnormalised inverse divided by the size).
void fft2(Eigen::MatrixXcd* m, bool inverse) {
  Eigen::FFT<double> fft;
  std::vector<std::complex<double>> in, out;
  for (int pass = 0; pass < 2; ++pass) {
    const Eigen::Index lines = pass == 0 ? m->rows() : m->cols();
    const Eigen::Index len = pass == 0 ? m->cols() : m->rows();
    in.resize(static_cast<size_t>(len));
    for (Eigen::Index l = 0; l < lines; ++l) {
      for (Eigen::Index k = 0; k < len; ++k)
        in[static_cast<size_t>(k)] = pass == 0 ? (*m)(l, k) : (*m)(k, l);
      if (inverse) {
        fft.inv(out, in);
      } else {
        fft.fwd(out, in);
      }
      for (Eigen::Index k = 0; k < len; ++k)
        (pass == 0 ? (*m)(l, k) : (*m)(k, l)) = out[static_cast<size_t>(k)];
    }
  }
}

// numpy/Julia fftfreq: sample frequencies of an n-point DFT at sampling rate fs.
double fftfreq(Eigen::Index i, Eigen::Index n, double fs) {
  const Eigen::Index k = i < (n + 1) / 2 ? i : i - n;
  return static_cast<double>(k) * fs / static_cast<double>(n);
}

Eigen::VectorXd axis(const H5Array& a, const std::string& path, const std::string& name) {
  if (a.dims.size() != 1 || a.values.size() < 2)
    throw Error(path + ": field '" + name + "' must be a vector of at least 2 values");
  Eigen::VectorXd v = Eigen::Map<const Eigen::VectorXd>(a.values.data(),
                                                        static_cast<Eigen::Index>(a.values.size()));
  for (Eigen::Index i = 1; i < v.size(); ++i)
    if (!(v[i] > v[i - 1])) throw Error(path + ": field '" + name + "' must increase");
  return v;
}

// Keys' cubic convolution kernel (a = -0.5) at distance x (in cells).
double keys(double x) {
  x = std::abs(x);
  if (x <= 1) return (1.5 * x - 2.5) * x * x + 1;
  if (x < 2) return ((-0.5 * x + 2.5) * x - 4) * x + 2;
  return 0.0;
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

bool AnomalyMap::covers(double lat, double lon) const {
  if (!(lat >= lat_rad[0] && lat <= lat_rad[lat_rad.size() - 1] && lon >= lon_rad[0] &&
        lon <= lon_rad[lon_rad.size() - 1]))
    return false;
  if (mask.size() == 0) return true;
  Eigen::Index i, j;
  double t, s;
  locate(lat_rad, lat, &i, &t);
  locate(lon_rad, lon, &j, &s);
  return mask(i + (t > 0.5), j + (s > 0.5)) != 0;
}

Eigen::Vector2d AnomalyMap::step_m() const {
  // Radii of curvature of the ellipsoid at the mean latitude (meridian and prime vertical).
  const double lat = 0.5 * (lat_rad[0] + lat_rad[lat_rad.size() - 1]);
  const double e2 = kWgs84E * kWgs84E, s2 = std::sin(lat) * std::sin(lat);
  const double rn = kWgs84A_m / std::sqrt(1 - e2 * s2);
  const double rm = kWgs84A_m * (1 - e2) / std::pow(1 - e2 * s2, 1.5);
  const double dlon = (lon_rad[lon_rad.size() - 1] - lon_rad[0]) / (lon_rad.size() - 1);
  const double dlat = (lat_rad[lat_rad.size() - 1] - lat_rad[0]) / (lat_rad.size() - 1);
  return {dlon * (rn + alt_m) * std::cos(lat), dlat * (rm + alt_m)};
}

Wavenumbers wavenumbers(double dx_m, double dy_m, int nx, int ny) {
  Wavenumbers w;
  w.kx = Eigen::MatrixXd::Zero(ny, nx);
  w.ky = Eigen::MatrixXd::Zero(ny, nx);
  for (int i = 0; i < ny; ++i) {
    for (int j = 0; j < nx; ++j) {
      if (nx * dx_m != 0) w.kx(i, j) = 2 * kPi * fftfreq(j, nx, 1.0 / dx_m);
      if (ny * dy_m != 0) w.ky(i, j) = 2 * kPi * fftfreq(i, ny, 1.0 / dy_m);
    }
  }
  w.k = (w.kx.array().square() + w.ky.array().square()).sqrt();
  return w;
}

Eigen::MatrixXd upward_continue(const Eigen::MatrixXd& map_nT, double dx_m, double dy_m,
                                double dz_m) {
  if (dz_m == 0) return map_nT;
  const auto ny = static_cast<int>(map_nT.rows()), nx = static_cast<int>(map_nT.cols());
  const Wavenumbers w = wavenumbers(dx_m, dy_m, nx, ny);
  Eigen::MatrixXcd f = map_nT.cast<std::complex<double>>();
  fft2(&f, false);
  f.array() *= (-w.k.array() * dz_m).exp().cast<std::complex<double>>();
  fft2(&f, true);
  return f.real();
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
  auto element = [&](const H5Array& a, size_t i, size_t j) {
    return julia ? a.at(j, i) : a.at(i, j);
  };
  m.map_nT.resize(m.lat_rad.size(), m.lon_rad.size());
  for (size_t i = 0; i < ny; ++i)
    for (size_t j = 0; j < nx; ++j)
      m.map_nT(static_cast<Eigen::Index>(i), static_cast<Eigen::Index>(j)) = element(grid, i, j);
  const H5Array alt = read_h5_array(path, "alt");
  if (alt.values.empty() || !std::isfinite(alt.values[0]))
    throw Error(path + ": field 'alt' must hold the map's altitude (m)");
  m.alt_m = alt.values[0];
  if (h5_has(path, "mask")) {
    const H5Array mask = read_h5_array(path, "mask");
    if (mask.dims != grid.dims) throw Error(path + ": field 'mask' must have the map's shape");
    m.mask.resize(m.map_nT.rows(), m.map_nT.cols());
    for (size_t i = 0; i < ny; ++i)
      for (size_t j = 0; j < nx; ++j)
        m.mask(static_cast<Eigen::Index>(i), static_cast<Eigen::Index>(j)) = element(mask, i, j);
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
