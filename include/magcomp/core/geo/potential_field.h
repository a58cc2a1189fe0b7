// magcomp: a potential field on a regular grid in the wavenumber domain: the grid's wavenumbers
// and upward continuation by FFT, the one the simulator's crustal field and the navigation maps
// use.
#pragma once

#include <Eigen/Core>
#include <vector>

namespace magcomp {

/// Wavenumbers (rad/m) of an ny x nx grid of steps dx, dy (m), in the FFT's order: k, kx, ky
/// (numpy's and Julia's fftfreq times 2 pi; k = |(kx, ky)|).
struct Wavenumbers {
  Eigen::MatrixXd k, kx, ky;
};
Wavenumbers wavenumbers(double dx_m, double dy_m, int nx, int ny);

/// Upward continuation of a gridded potential field (ny x nx, steps dx_m east and dy_m north, m)
/// by dz_m (m, >= 0) in the wavenumber domain (exp(-k dz)), without padding: the grid is taken as
/// periodic. dz_m = 0 returns the grid itself.
Eigen::MatrixXd upward_continue(const Eigen::MatrixXd& map_nT, double dx_m, double dy_m,
                                double dz_m);

/// The same continuation to several heights dz_m (m, each >= 0) with one forward transform:
/// element k equals upward_continue(map_nT, dx_m, dy_m, dz_m[k]).
std::vector<Eigen::MatrixXd> upward_continue(const Eigen::MatrixXd& map_nT, double dx_m,
                                             double dy_m, const std::vector<double>& dz_m);

}  // namespace magcomp
