// magcomp: wavenumbers and upward continuation of a gridded potential field.
#include "magcomp/core/geo/potential_field.h"

#include <complex>

#include "magcomp/core/math/constants.h"
#include "magcomp/core/math/fft2.h"

namespace magcomp {
namespace {

// numpy/Julia fftfreq: sample frequencies of an n-point DFT at sampling rate fs.
double fftfreq(Eigen::Index i, Eigen::Index n, double fs) {
  const Eigen::Index k = i < (n + 1) / 2 ? i : i - n;
  return static_cast<double>(k) * fs / static_cast<double>(n);
}

}  // namespace

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

std::vector<Eigen::MatrixXd> upward_continue(const Eigen::MatrixXd& map_nT, double dx_m,
                                             double dy_m, const std::vector<double>& dz_m) {
  std::vector<Eigen::MatrixXd> out;
  out.reserve(dz_m.size());
  Eigen::MatrixXcd spectrum;
  Eigen::MatrixXd k;
  for (const double dz : dz_m) {
    if (dz == 0) {
      out.push_back(map_nT);
      continue;
    }
    if (spectrum.size() == 0) {
      k = wavenumbers(dx_m, dy_m, static_cast<int>(map_nT.cols()), static_cast<int>(map_nT.rows()))
              .k;
      spectrum = map_nT.cast<std::complex<double>>();
      fft2(&spectrum, false);
    }
    Eigen::MatrixXcd f = spectrum.array() * (-k.array() * dz).exp().cast<std::complex<double>>();
    fft2(&f, true);
    out.push_back(f.real());
  }
  return out;
}

Eigen::MatrixXd upward_continue(const Eigen::MatrixXd& map_nT, double dx_m, double dy_m,
                                double dz_m) {
  return upward_continue(map_nT, dx_m, dy_m, std::vector<double>{dz_m}).front();
}

}  // namespace magcomp
