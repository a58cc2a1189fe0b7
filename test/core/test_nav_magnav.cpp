// The navigation core against MagNav.jl's own test vectors (test/data/reference/magnav_nav,
// ekf_test.h5): map wavenumbers and upward continuation, the Pinson matrices, the EKF's first and
// last state and covariance, the CRLB, at MagNav.jl's tolerances.
#include <gtest/gtest.h>

#include <cmath>

#include "magcomp/core/error.h"
#include "magcomp/core/geo/potential_field.h"
#include "magcomp/core/io/h5_array.h"
#include "magcomp/core/math/constants.h"
#include "magcomp/core/nav/anomaly_map.h"
#include "magcomp/core/nav/ekf.h"
#include "magcomp/core/nav/nav_model.h"
#include "magcomp/core/nav/pinson.h"
#include "nav_example.h"
#include "test_util.h"

namespace magcomp::nav {
namespace {

const std::string& vectors() {
  static const std::string path = test::reference_dir() + "/magnav_nav/ekf_test.h5";
  return path;
}

double scalar(const std::string& name) { return read_h5_array(vectors(), name).values.at(0); }

Eigen::VectorXd vec(const std::string& name) {
  const H5Array a = read_h5_array(vectors(), name);
  return Eigen::Map<const Eigen::VectorXd>(a.values.data(),
                                           static_cast<Eigen::Index>(a.values.size()));
}

Eigen::MatrixXd mat(const std::string& name) {
  const H5Array a = read_h5_array(vectors(), name);
  Eigen::MatrixXd m(static_cast<Eigen::Index>(a.dims.at(0)),
                    static_cast<Eigen::Index>(a.dims.at(1)));
  for (Eigen::Index i = 0; i < m.rows(); ++i)
    for (Eigen::Index j = 0; j < m.cols(); ++j)
      m(i, j) = a.at(static_cast<size_t>(i), static_cast<size_t>(j));
  return m;
}

// Slice [:, :, k] of a 3-D array.
Eigen::MatrixXd slice(const H5Array& a, size_t k) {
  Eigen::MatrixXd m(static_cast<Eigen::Index>(a.dims.at(0)),
                    static_cast<Eigen::Index>(a.dims.at(1)));
  for (Eigen::Index i = 0; i < m.rows(); ++i)
    for (Eigen::Index j = 0; j < m.cols(); ++j)
      m(i, j) = a.at(static_cast<size_t>(i), static_cast<size_t>(j), k);
  return m;
}

// The "traj" or "ins" group as a track (angles converted from degrees, as MagNav.jl's tests do).
NavTrack track(const std::string& group) {
  NavTrack t;
  t.dt_s = scalar("params/dt");
  t.lat_rad = vec(group + "/lat") * kDegToRad;
  t.lon_rad = vec(group + "/lon") * kDegToRad;
  t.alt_m = vec(group + "/alt");
  t.vn_mps = vec(group + "/vn");
  t.ve_mps = vec(group + "/ve");
  t.vd_mps = vec(group + "/vd");
  t.fn_mps2 = vec(group + "/fn");
  t.fe_mps2 = vec(group + "/fe");
  t.fd_mps2 = vec(group + "/fd");
  const H5Array cnb = read_h5_array(vectors(), group + "/Cnb");
  for (size_t k = 0; k < cnb.dims.at(2); ++k) t.cnb.emplace_back(slice(cnb, k));
  return t;
}

AnomalyMap test_map() {
  AnomalyMap m;
  m.map_nT = mat("map/map");
  m.lon_rad = vec("map/xx") * kDegToRad;
  m.lat_rad = vec("map/yy") * kDegToRad;
  m.alt_m = scalar("map/alt");
  return m;
}

FilterSettings settings() {
  FilterSettings s;
  s.p0 = mat("ekf/P0");
  s.qd = mat("ekf/Qd");
  s.r_nT2 = scalar("ekf/R");
  s.taus = {scalar("params/baro_tau"), scalar("params/acc_tau"), scalar("params/gyro_tau"),
            scalar("params/meas_tau")};
  return s;
}

// Julia's isapprox(a, b) (rtol = sqrt(eps), on the norm), and its atol form.
double relative(const Eigen::MatrixXd& a, const Eigen::MatrixXd& b) {
  return (a - b).norm() / std::max(a.norm(), b.norm());
}

TEST(NavMagNav, WavenumbersAndUpwardContinuation) {
  const Eigen::MatrixXd map = mat("map/map");
  const double dx = scalar("map/dx"), dy = scalar("map/dy"), dz = scalar("map/dz");
  const Wavenumbers w =
      wavenumbers(dx, dy, static_cast<int>(map.cols()), static_cast<int>(map.rows()));
  EXPECT_LT(relative(w.k, mat("map/k")), 1.5e-8);
  EXPECT_LT(relative(w.kx, mat("map/kx")), 1.5e-8);
  EXPECT_LT(relative(w.ky, mat("map/ky")), 1.5e-8);
  const Eigen::MatrixXd up = upward_continue(map, dx, dy, dz);
  const double rel = relative(up, mat("map/map_out"));
  std::printf("  upward continuation by %.0f m: relative difference %.2e (largest %.2e nT)\n", dz,
              rel, (up - mat("map/map_out")).cwiseAbs().maxCoeff());
  EXPECT_LT(rel, 1.5e-8);
}

TEST(NavMagNav, PinsonMatricesAtTheFirstSample) {
  const NavTrack t = track("traj");
  const ErrorModelTaus taus = settings().taus;
  const NavPoint p = t.point(0);
  EXPECT_LT(relative(pinson_dynamics(p, taus, false), mat("pinson/P17")), 1.5e-8);
  EXPECT_LT(relative(pinson_dynamics(p, taus, true), mat("pinson/P18")), 1.5e-8);
  const double rel = relative(pinson_transition(p, taus, true, t.dt_s), mat("pinson/Phi"));
  std::printf("  Phi = exp(F dt): relative difference %.2e\n", rel);
  EXPECT_LT(rel, 1.5e-8);
}

TEST(NavMagNav, EkfFirstAndLastStateAndCovariance) {
  const FilterResult r = run_ekf(track("ins"), vec("traj/mag_1_c"), test_map(), settings());
  const Eigen::MatrixXd x_ref = mat("ekf/x_out");
  const H5Array p_ref = read_h5_array(vectors(), "ekf/P_out");
  const Eigen::Index last = r.x.cols() - 1;
  const double dx0 = (r.x.col(0) - x_ref.col(0)).cwiseAbs().maxCoeff();
  const double dx1 = (r.x.col(last) - x_ref.col(1)).cwiseAbs().maxCoeff();
  const double dp0 = (r.p.front() - slice(p_ref, 0)).cwiseAbs().maxCoeff();
  const double dp1 = (r.p.back() - slice(p_ref, 1)).cwiseAbs().maxCoeff();
  std::printf("  EKF vs MagNav.jl: |x| first %.2e last %.2e; |P| first %.2e last %.2e\n", dx0, dx1,
              dp0, dp1);
  EXPECT_LT(dx0, 1e-6);
  EXPECT_LT(dx1, 1e-3);
  EXPECT_LT(dp0, 1e-6);
  EXPECT_LT(dp1, 1e-3);
}

TEST(NavMagNav, CrlbFirstAndLast) {
  const std::vector<Eigen::MatrixXd> p = crlb(track("traj"), test_map(), settings());
  const H5Array ref = read_h5_array(vectors(), "ekf/crlb_P");
  const double d0 = (p.front() - slice(ref, 0)).cwiseAbs().maxCoeff();
  const double d1 = (p.back() - slice(ref, 1)).cwiseAbs().maxCoeff();
  std::printf("  CRLB vs MagNav.jl: first %.2e, last %.2e\n", d0, d1);
  EXPECT_LT(d0, 1e-6);
  EXPECT_LT(d1, 1e-6);
}

TEST(NavMagNav, MapFileOfTheSimpleExample) {
  const AnomalyMap m = read_anomaly_map(test::reference_dir() + "/magnav_nav/simple_map.h5");
  std::printf("  simple_map.h5: %ld x %ld cells, alt %.0f m, steps %.0f x %.0f m\n",
              static_cast<long>(m.map_nT.rows()), static_cast<long>(m.map_nT.cols()), m.alt_m,
              m.step_m().x(), m.step_m().y());
  EXPECT_EQ(m.map_nT.rows(), 100);
  EXPECT_NEAR(m.alt_m, 305.0, 1e-9);
  EXPECT_LT(m.lat_rad.cwiseAbs().maxCoeff(), kPi / 2);  // degrees converted
  // Bilinear at a node is the node; between nodes, the average of the four.
  EXPECT_NEAR(m.value(m.lat_rad[10], m.lon_rad[20]), m.map_nT(10, 20), 1e-9);
  const double mid =
      m.value(0.5 * (m.lat_rad[10] + m.lat_rad[11]), 0.5 * (m.lon_rad[20] + m.lon_rad[21]));
  EXPECT_NEAR(mid,
              0.25 * (m.map_nT(10, 20) + m.map_nT(11, 20) + m.map_nT(10, 21) + m.map_nT(11, 21)),
              1e-9);
  EXPECT_THROW(read_anomaly_map(test::reference_dir() + "/magnav_nav/simple_xyz.h5"), Error);
}

TEST(NavMagNav, FilterModelFromSigmas) {
  // MagNav.jl's create_model with its test's parameters gives its P0 and Qd.
  ModelSigmas m;
  m.init_pos_m = scalar("params/init_pos_sigma");
  m.init_alt_m = scalar("params/init_alt_sigma");
  m.init_vel_mps = scalar("params/init_vel_sigma");
  m.init_att_rad = scalar("params/init_att_sigma");
  m.meas_var_nT2 = scalar("params/meas_R");
  m.vrw = std::sqrt(scalar("params/VRW_var"));
  m.arw = std::sqrt(scalar("params/ARW_var"));
  m.baro_m = scalar("params/baro_std");
  m.ha_m = scalar("params/ha_sigma");
  m.a_hat_mps2 = scalar("params/a_hat_sigma");
  m.acc_mps2 = scalar("params/acc_sigma");
  m.gyro_rps = scalar("params/gyro_sigma");
  m.fogm_nT = scalar("params/meas_sigma");
  m.taus = settings().taus;
  const FilterSettings f = filter_model(scalar("params/dt"), vec("traj/lat")[0] * kDegToRad, m);
  EXPECT_LT(relative(f.p0, mat("ekf/P0")), 1.5e-8);
  EXPECT_LT(relative(f.qd, mat("ekf/Qd")), 1.5e-8);
  EXPECT_NEAR(f.r_nT2, scalar("ekf/R"), 1e-12);
}

TEST(NavMagNav, TheSimpleExampleNavigatesToAFewMetres) {
  // MagNav.jl's examples/simple_magnav.jl: 100 s at 1 Hz, its settings (the ModelSigmas
  // defaults), the compensated scalar against the map. MagNav.jl states about 7 m DRMS with a
  // cubic map interpolation; magcomp's map is bilinear.
  const std::string dir = test::reference_dir() + "/magnav_nav/";
  const auto& col = test::simple_example_column;
  const Eigen::VectorXd tt = col("tt");
  const double dt = tt[1] - tt[0];
  const NavTrack ins = track_from_positions(
      dt, col("ins_lat") * kDegToRad, col("ins_lon") * kDegToRad, col("ins_alt"),
      col("ins_roll") * kDegToRad, col("ins_pitch") * kDegToRad, col("ins_yaw") * kDegToRad);
  const NavTrack truth = track_from_positions(dt, col("lat") * kDegToRad, col("lon") * kDegToRad,
                                              col("alt"), col("roll") * kDegToRad,
                                              col("pitch") * kDegToRad, col("yaw") * kDegToRad);
  const AnomalyMap map = read_anomaly_map(dir + "simple_map.h5");
  const FilterSettings s = filter_model(dt, truth.lat_rad[0], ModelSigmas{});
  const FilterResult r = run_ekf(ins, col("mag_1_c"), map, s);
  const double filt = position_errors(ins, r.x, truth.lat_rad, truth.lon_rad).drms_m;
  const double ins_only = position_errors(ins, {}, truth.lat_rad, truth.lon_rad).drms_m;
  const double bound = covariance_drms_m(crlb(truth, map, s), truth.lat_rad);
  std::printf(
      "  simple example: filter DRMS %.1f m, INS alone %.1f m, CRLB %.1f m (MagNav.jl: ~7 m)\n",
      filt, ins_only, bound);
  // This INS drifts only 2 m in 100 s: the filter must stay there and within the bound.
  EXPECT_LT(filt, 1.5 * bound);
  EXPECT_LT(filt, 1.05 * ins_only);
}

}  // namespace
}  // namespace magcomp::nav
