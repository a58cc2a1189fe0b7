// magcomp tests: a closed-form flight whose scalar field is exactly Earth + a known TL model.
#pragma once

#include <Eigen/Geometry>
#include <cmath>

#include "magcomp/core/io/flight_data.h"
#include "magcomp/core/model/model.h"

namespace magcomp::test {

/// Attitude oscillates (roll +-10 deg, pitch +-5 deg, yaw +-5 deg around four headings), the Earth
/// field is constant in NED. The vector sensor reads the Earth field in the body frame; the
/// scalar reads |B_earth| + A(model) c_true (the TL model itself, so a fit can recover c_true).
inline FlightData synthetic_tl_flight(const Model& model, const Eigen::VectorXd& c_true,
                                      int n = 6000, double bias_nT = 0.0) {
  FlightData d;
  const Eigen::Vector3d earth_ned(17000.0, -4000.0, 50000.0);
  Eigen::VectorXd tt(n), bx(n), by(n), bz(n), line(n);
  for (int i = 0; i < n; ++i) {
    const double t = 0.1 * i;
    const int leg = (4 * i) / n;
    const double yaw = leg * M_PI / 2 + 5.0 * M_PI / 180 * std::sin(2 * M_PI * 0.07 * t);
    const double pitch = 5.0 * M_PI / 180 * std::sin(2 * M_PI * 0.11 * t + 0.3);
    const double roll = 10.0 * M_PI / 180 * std::sin(2 * M_PI * 0.19 * t + 1.1);
    // Body (x forward, y right, z down for the NED rotation), then to x fwd, y left, z up.
    const Eigen::Matrix3d r_nb = (Eigen::AngleAxisd(yaw, Eigen::Vector3d::UnitZ()) *
                                  Eigen::AngleAxisd(pitch, Eigen::Vector3d::UnitY()) *
                                  Eigen::AngleAxisd(roll, Eigen::Vector3d::UnitX()))
                                     .toRotationMatrix();
    const Eigen::Vector3d b_frd = r_nb.transpose() * earth_ned;
    tt[i] = 40000.0 + t;
    bx[i] = b_frd.x();
    by[i] = -b_frd.y();
    bz[i] = -b_frd.z();
    line[i] = 1000.0 + leg + 0.01;
  }
  d.set("tt", tt);
  d.set("line", line);
  d.set(model.vector + "_x", bx);
  d.set(model.vector + "_y", by);
  d.set(model.vector + "_z", bz);
  const double total = earth_ned.norm();
  d.set(model.scalar, Eigen::VectorXd::Constant(n, total));
  const Eigen::VectorXd aircraft = design_matrix(model, d) * c_true;
  d.set(model.scalar, (Eigen::VectorXd::Constant(n, total + bias_nT) + aircraft).eval());
  d.set("mag_1_c", Eigen::VectorXd::Constant(n, total));
  return d;
}

/// The 16-term TL model the synthetic flights are fitted with (induced5 / eddy8 drop the columns
/// that are exactly dependent when |B| is constant), on two separate calibration lines.
inline Model tl16_model() {
  Model m;
  m.scalar = "mag_5_uc";
  m.vector = "flux_c";
  m.terms = {"permanent", "induced5", "eddy8"};
  m.fit.lambda = 1e-9;
  m.fit.lines = {1000.01, 1002.01};
  return m;
}

/// p known coefficients (nT per unit of each column): the permanent ones large, the rest
/// +-40 nT.
inline Eigen::VectorXd known_coefficients(Eigen::Index p) {
  Eigen::VectorXd c(p);
  for (Eigen::Index j = 0; j < p; ++j) c[j] = 40.0 * std::sin(1.7 * j + 0.4) + (j < 3 ? 300 : 0);
  return c;
}

}  // namespace magcomp::test
