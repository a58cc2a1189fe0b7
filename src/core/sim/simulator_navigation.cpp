// magcomp simulator: the anomaly map a navigator carries over the flight, and a drifting
// navigation-grade INS (see simulator_steps.h).
#include <cmath>
#include <cstdio>
#include <random>

#include "magcomp/core/geo/potential_field.h"
#include "magcomp/core/math/constants.h"
#include "magcomp/core/nav/nav_model.h"
#include "magcomp/core/nav/pinson.h"
#include "magcomp/core/sim/crustal_field.h"
#include "simulator_steps.h"

namespace magcomp::sim::steps {

// The anomaly the flight samples, as a map a navigator would carry: a latitude/longitude grid over
// the flight and a margin, at the flight's mean height above the (flat) ground, its cell the
// anomaly grid's. The flight at that height samples exactly this field.
void Simulator::navigation_map(const Eigen::MatrixXd& ground) {
  const double mean_alt = tr_.alt_m.mean();
  const double cell = s_.anomaly_grid_m, margin = s_.nav_map_margin_m;
  const Eigen::MatrixXd grid = upward_continue(ground, cell, cell, mean_alt - s_.terrain_m);
  const double n0 = tr_.north_m.minCoeff() - margin, n1 = tr_.north_m.maxCoeff() + margin;
  const double e0 = tr_.east_m.minCoeff() - margin, e1 = tr_.east_m.maxCoeff() + margin;
  const auto ny = static_cast<Eigen::Index>(std::ceil((n1 - n0) / cell)) + 1;
  const auto nx = static_cast<Eigen::Index>(std::ceil((e1 - e0) / cell)) + 1;
  const double deg_per_north_m = 1.0 / kMeanEarthRadius_m / kDegToRad;
  const double deg_per_east_m =
      1.0 / (kMeanEarthRadius_m * std::cos(s_.origin_lat_deg * kDegToRad)) / kDegToRad;
  nav::AnomalyMap& m = sim_.map;
  m.alt_m = mean_alt;
  m.lat_rad.resize(ny);
  m.lon_rad.resize(nx);
  m.map_nT.resize(ny, nx);
  m.mask = Eigen::MatrixXd::Ones(ny, nx);
  for (Eigen::Index i = 0; i < ny; ++i)
    m.lat_rad[i] = (s_.origin_lat_deg + (n0 + cell * i) * deg_per_north_m) * kDegToRad;
  for (Eigen::Index j = 0; j < nx; ++j)
    m.lon_rad[j] = (s_.origin_lon_deg + (e0 + cell * j) * deg_per_east_m) * kDegToRad;
  for (Eigen::Index i = 0; i < ny; ++i)
    for (Eigen::Index j = 0; j < nx; ++j)
      m.map_nT(i, j) = periodic_value(grid, cell, n0 + cell * i, e0 + cell * j);
}

// A navigation-grade INS: its position errors propagated with the filter's own error model
// (Pinson dynamics, MagNav.jl's default sigmas) from an initial error drawn from P0, on a random
// stream of their own. The attitude and velocities stay as recorded.
void Simulator::drifting_ins() {
  const double dt = 1.0 / s_.sample_rate_hz;
  const Eigen::VectorXd lat = tr_.lat_deg * kDegToRad, lon = tr_.lon_deg * kDegToRad;
  const nav::NavTrack truth =
      nav::track_from_positions(dt, lat, lon, tr_.alt_m, tr_.roll_rad, tr_.pitch_rad, tr_.yaw_rad);
  const nav::FilterSettings model = nav::filter_model(dt, lat[0], nav::ModelSigmas{});
  std::mt19937_64 rng(s_.nav_ins_seed * 0x9E3779B97F4A7C15ULL + s_.seed);
  std::normal_distribution<double> normal(0.0, 1.0);
  const Eigen::VectorXd sd0 = model.p0.diagonal().cwiseSqrt(),
                        sdq = model.qd.diagonal().cwiseSqrt();
  Eigen::VectorXd x(18);
  for (int k = 0; k < 18; ++k) x[k] = sd0[k] * normal(rng);
  x[17] = 0.0;  // the catch-all is the filter's, not the INS's
  Eigen::VectorXd ins_lat(n_), ins_lon(n_), ins_alt(n_);
  for (Eigen::Index i = 0; i < n_; ++i) {
    ins_lat[i] = lat[i] + x[0];
    ins_lon[i] = lon[i] + x[1];
    ins_alt[i] = tr_.alt_m[i] + x[2];
    const Eigen::MatrixXd phi = nav::pinson_transition(truth.point(i), model.taus, true, dt);
    x = phi * x;
    for (int k = 0; k < 17; ++k) x[k] += sdq[k] * normal(rng);
  }
  sim_.flight.set("ins_lat", ins_lat);
  sim_.flight.set("ins_lon", ins_lon);
  sim_.flight.set("ins_alt", ins_alt);
  const nav::PositionErrors e =
      nav::position_errors(nav::track_from_positions(dt, ins_lat, ins_lon, ins_alt, tr_.roll_rad,
                                                     tr_.pitch_rad, tr_.yaw_rad),
                           {}, lat, lon);
  char line[96];
  std::snprintf(line, sizeof(line), "ins_drift_drms_m: %.3f\n", e.drms_m);
  sim_.truth_yaml += line;
}

}  // namespace magcomp::sim::steps
