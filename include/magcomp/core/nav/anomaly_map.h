// magcomp: a magnetic anomaly map on a regular latitude/longitude grid: bilinear value and
// gradient, upward continuation (geo/potential_field), read from MagNav.jl's HDF5 map files.
#pragma once

#include <Eigen/Core>
#include <string>
#include <vector>

namespace magcomp::nav {

/// Grid: map_nT(i, j) at latitude lat_rad[i], longitude lon_rad[j] (both increasing, uniform
/// steps), altitude alt_m above the WGS-84 ellipsoid; mask(i, j) != 0 where the cell is valid
/// (empty: all valid). A masked cell holds a finite filler, never read where covers() is false.
struct AnomalyMap {
  Eigen::MatrixXd map_nT;
  Eigen::VectorXd lat_rad, lon_rad;
  double alt_m = 0.0;
  Eigen::MatrixXd mask;
  /// The map's own error, 1-sigma nT: the file's `error_sigma_nT` when it carries one, else
  /// kDefaultMapSigma_nT (a stated default: a survey map's level and leveling error).
  double error_sigma_nT = kDefaultMapSigma_nT;
  static constexpr double kDefaultMapSigma_nT = 0.3;
  /// How value() interpolates: bilinear (MagNav.jl's :linear, its test vectors') or cubic
  /// convolution (Keys, a = -0.5: C1, exact on quadratics; MagNav.jl's examples use a cubic map).
  enum class Interpolation { Linear, Cubic };
  Interpolation interpolation = Interpolation::Linear;

  /// Value at (lat, lon), rad (the edge cells extended beyond the grid), nT.
  double value(double lat_rad, double lon_rad) const;
  /// Gradient (dmap/dlat nT/rad, dmap/dlon nT/rad) by a central difference of 1e-8 rad (as
  /// MagNav.jl's map_grad: the float literal 1.0f-8).
  Eigen::Vector2d gradient(double lat_rad, double lon_rad) const;
  /// Whether (lat, lon) lies inside the grid and every cell its interpolation reads is valid.
  bool covers(double lat_rad, double lon_rad) const;
  /// covers() and value() in one: the value in *value_nT when covered (a particle filter's inner
  /// loop).
  bool covered_value(double lat_rad, double lon_rad, double* value_nT) const;
  /// Grid steps in metres at the map's mean latitude: east (x) and north (y).
  Eigen::Vector2d step_m() const;
  /// The map's second derivatives at the grid node nearest (lat, lon), rad: [d2/dlat2,
  /// d2/dlat dlon; d2/dlat dlon, d2/dlon2] in nT/rad^2, by second differences of the nodes about
  /// it. Zero where a node it reads is masked or lies off the grid.
  Eigen::Matrix2d curvature(double lat_rad, double lon_rad) const;
  /// The variance the map's representation adds to one measurement at (lat, lon), rad, beyond
  /// the survey's own error, nT^2: the interpolation's error (bilinear: half the curvature times
  /// t(1-t) step^2 along each axis, squared; cubic convolution, exact on quadratics: none) plus the
  /// linearisation of the map over the position's uncertainty p_rad2 (2 x 2, lat/lon, rad^2):
  /// 1/2 tr((C P)^2) with C the curvature, the variance of the quadratic term a linear update
  /// leaves out.
  double representation_var_nT2(double lat_rad, double lon_rad,
                                const Eigen::Matrix2d& p_rad2) const;
};

/// The map continued up to alt_m (>= the map's altitude), by geo/potential_field's
/// upward_continue on the grid's steps in metres (step_m()).
AnomalyMap continued_to(const AnomalyMap& map, double alt_m);

/// Reads a map file with MagNav.jl's names: `map` (ny x nx, nT), `xx` (longitude), `yy`
/// (latitude), `alt` (m), optional `mask`. Validated on reading: the axes finite, increasing and
/// uniform, in degrees or radians; the declared sizes checked against the file before any
/// allocation; non-finite cells masked; a cell beyond 1e6 nT, an all-masked map or an altitude
/// beyond 100 km refused. The grid is taken in MagNav.jl's layout (written from
/// Julia: dimensions (nx, ny)) unless its dimensions are (ny, nx) and it is not square. Angles in
/// degrees are recognised (|yy| > pi/2 or |xx| > pi) and converted. Throws magcomp::Error naming
/// the file and field.
AnomalyMap read_anomaly_map(const std::string& path);

/// Writes a map in MagNav.jl's layout (Julia's: `map` stored with dimensions (nx, ny); `xx`, `yy`
/// in degrees; `alt`; `mask`), atomically and never over one of `inputs`.
void write_anomaly_map(const AnomalyMap& map, const std::string& path,
                       const std::vector<std::string>& inputs = {});

}  // namespace magcomp::nav
