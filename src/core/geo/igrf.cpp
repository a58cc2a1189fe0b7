// magcomp: IGRF synthesis.
#include "magcomp/core/geo/igrf.h"

#include <cmath>
#include <cstdlib>
#include <fstream>
#include <sstream>

#include "magcomp/core/error.h"
#include "magcomp/core/geo/wgs84.h"
#include "magcomp/core/io/paths.h"
#include "magcomp/core/math/constants.h"

namespace magcomp {
namespace {

constexpr double kReferenceRadiusKm = 6371.2;
constexpr double kWgs84A_km = kWgs84SemiMajor_m / 1000.0;

inline size_t idx(int n, int m) { return static_cast<size_t>(n * (n + 1) / 2 + m); }

}  // namespace

double FieldNED::total_nT() const {
  return std::sqrt(north_nT * north_nT + east_nT * east_nT + down_nT * down_nT);
}

Igrf Igrf::load(const std::string& path) {
  std::ifstream f(path);
  if (!f) throw Error(path + ": IGRF coefficient file not found or not readable");
  Igrf model;
  std::string line;
  int line_no = 0;
  int header = 0;
  int nmax = 0, n_epochs = 0;
  int pending_n = -1, pending_m = -1;  // a g row waiting for its h row
  while (std::getline(f, line)) {
    ++line_no;
    if (line.empty() || line[0] == '#') continue;
    std::istringstream s(line);
    if (header == 0) {
      int nmin = 0;
      if (!(s >> nmin >> nmax >> n_epochs) || nmax < 1 || n_epochs < 1) {
        throw Error(path + ": line " + std::to_string(line_no) + ": bad SHC header");
      }
      model.nmax_ = nmax;
      const size_t count = idx(nmax, nmax) + 1;
      model.g_.assign(static_cast<size_t>(n_epochs), std::vector<double>(count, 0.0));
      model.h_ = model.g_;
      header = 1;
      continue;
    }
    if (header == 1) {
      double e;
      while (s >> e) model.epochs_.push_back(e);
      if (static_cast<int>(model.epochs_.size()) != n_epochs) {
        throw Error(path + ": line " + std::to_string(line_no) + ": expected " +
                    std::to_string(n_epochs) + " epochs");
      }
      header = 2;
      continue;
    }
    int n = 0, m = 0;
    if (!(s >> n >> m) || n < 1 || n > nmax || m < 0 || m > n) {
      throw Error(path + ": line " + std::to_string(line_no) + ": bad coefficient row");
    }
    std::vector<double> values;
    double v;
    while (s >> v) values.push_back(v);
    if (static_cast<int>(values.size()) != n_epochs) {
      throw Error(path + ": line " + std::to_string(line_no) + ": expected " +
                  std::to_string(n_epochs) + " values");
    }
    const bool is_h = (m > 0 && pending_n == n && pending_m == m);
    for (int e = 0; e < n_epochs; ++e) {
      (is_h ? model.h_ : model.g_)[static_cast<size_t>(e)][idx(n, m)] =
          values[static_cast<size_t>(e)];
    }
    if (m > 0 && !is_h) {
      pending_n = n;
      pending_m = m;
    } else {
      pending_n = pending_m = -1;
    }
  }
  if (header < 2) throw Error(path + ": no coefficients found");
  return model;
}

Igrf Igrf::installed() {
  const char* env = std::getenv("MAGCOMP_IGRF_FILE");
  return Igrf::load(env && *env ? std::string(env) : share_dir() + "/config/igrf14.shc");
}

FieldNED Igrf::geocentric(double colat_deg, double lon_deg, double r_km, double year) const {
  if (!(year >= epochs_.front() && year <= epochs_.back())) {
    throw Error("igrf: year " + std::to_string(year) + " outside the model's epochs " +
                std::to_string(epochs_.front()) + ".." + std::to_string(epochs_.back()));
  }
  size_t e = 0;
  while (e + 2 < epochs_.size() && year >= epochs_[e + 1]) ++e;
  const double w = (year - epochs_[e]) / (epochs_[e + 1] - epochs_[e]);
  const int nmax = nmax_;
  const double theta = colat_deg * kDegToRad, phi = lon_deg * kDegToRad;
  const double x = std::cos(theta), s = std::sin(theta);
  // Unnormalised associated Legendre functions (no Condon-Shortley phase), P[n][m], m <= n + 1.
  std::vector<std::vector<double>> p(static_cast<size_t>(nmax + 2),
                                     std::vector<double>(static_cast<size_t>(nmax + 3), 0.0));
  for (int m = 0; m <= nmax + 1; ++m) {
    double pmm = 1.0;
    for (int k = 1; k <= m; ++k) pmm *= (2.0 * k - 1.0) * s;
    if (m <= nmax + 1) p[static_cast<size_t>(m)][static_cast<size_t>(m)] = pmm;
    if (m + 1 <= nmax + 1)
      p[static_cast<size_t>(m + 1)][static_cast<size_t>(m)] = x * (2.0 * m + 1.0) * pmm;
    for (int n = m + 2; n <= nmax + 1; ++n) {
      p[static_cast<size_t>(n)][static_cast<size_t>(m)] =
          ((2.0 * n - 1.0) * x * p[static_cast<size_t>(n - 1)][static_cast<size_t>(m)] -
           (n + m - 1.0) * p[static_cast<size_t>(n - 2)][static_cast<size_t>(m)]) /
          (n - m);
    }
  }
  auto P = [&](int n, int m) -> double {
    if (m < 0 || m > n) return 0.0;
    return p[static_cast<size_t>(n)][static_cast<size_t>(m)];
  };
  double bx = 0, by = 0, bz = 0;
  for (int n = 1; n <= nmax; ++n) {
    const double ratio = std::pow(kReferenceRadiusKm / r_km, n + 2);
    for (int m = 0; m <= n; ++m) {
      // Schmidt semi-normalisation sqrt((2 - delta_m0) (n-m)! / (n+m)!).
      double fac = 1.0;
      for (int k = n - m + 1; k <= n + m; ++k) fac /= k;
      const double schmidt = std::sqrt((m == 0 ? 1.0 : 2.0) * fac);
      const double g = (1 - w) * g_[e][idx(n, m)] + w * g_[e + 1][idx(n, m)];
      const double h = (1 - w) * h_[e][idx(n, m)] + w * h_[e + 1][idx(n, m)];
      const double cm = std::cos(m * phi), sm = std::sin(m * phi);
      const double pnm = schmidt * P(n, m);
      const double dpnm =
          schmidt *
          (m == 0 ? -P(n, 1) : 0.5 * ((n + m) * (n - m + 1.0) * P(n, m - 1) - P(n, m + 1)));
      bx += ratio * (g * cm + h * sm) * dpnm;
      bz -= ratio * (n + 1.0) * (g * cm + h * sm) * pnm;
      if (s > 1e-12) by += ratio * m * (g * sm - h * cm) * pnm / s;
    }
  }
  return {bx, by, bz};
}

FieldNED Igrf::geodetic(double lat_deg, double lon_deg, double height_m, double year) const {
  const double lat = lat_deg * kDegToRad;
  const double h = height_m / 1000.0;
  const double e2 = kWgs84Flattening * (2.0 - kWgs84Flattening);
  const double sl = std::sin(lat), cl = std::cos(lat);
  const double nu = kWgs84A_km / std::sqrt(1.0 - e2 * sl * sl);
  const double rho = (nu + h) * cl;             // distance from the axis, km
  const double z = (nu * (1.0 - e2) + h) * sl;  // along the axis, km
  const double r = std::hypot(rho, z);
  const double lat_gc = std::atan2(z, rho);
  const FieldNED gc = geocentric(90.0 - lat_gc / kDegToRad, lon_deg, r, year);
  const double d = lat - lat_gc;  // geodetic minus geocentric latitude
  FieldNED out;
  out.north_nT = gc.north_nT * std::cos(d) + gc.down_nT * std::sin(d);
  out.east_nT = gc.east_nT;
  out.down_nT = -gc.north_nT * std::sin(d) + gc.down_nT * std::cos(d);
  return out;
}

}  // namespace magcomp
