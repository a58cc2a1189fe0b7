// The navigator online: the streaming track against closed-form motion, and the streaming
// navigator against the batch filter (run_ekf) on MagNav.jl's simple example, with late,
// missing and stray measurements, gaps and positions off the map.
#include <gtest/gtest.h>

#include <cmath>

#include "magcomp/core/geo/local_enu.h"
#include "magcomp/core/io/h5_array.h"
#include "magcomp/core/math/constants.h"
#include "magcomp/core/nav/anomaly_map.h"
#include "magcomp/core/nav/ekf.h"
#include "magcomp/core/nav/flight_run.h"
#include "magcomp/core/nav/nav_model.h"
#include "magcomp/core/nav/streaming_navigator.h"
#include "magcomp/core/nav/streaming_track.h"
#include "nav_example.h"
#include "test_util.h"

namespace magcomp::nav {
namespace {

TEST(NavStreaming, TrackOfAConstantAccelerationIsExact) {
  // Altitude h(t) = 1000 + 0.5 c t^2 and a northward drift at 50 m/s: central differences are
  // exact on quadratics, so vd = -c t and fd = -c - g inside; one-sided at the ends.
  const double dt = 0.1, c = 0.8, lat0 = 45 * kDegToRad;
  const int n = 40;
  Eigen::VectorXd lat(n), lon(n), alt(n), zero = Eigen::VectorXd::Zero(n);
  for (int i = 0; i < n; ++i) {
    const double t = i * dt;
    lat[i] = lat0 + 50.0 * t / dlat_to_north_m(1.0, lat0);
    lon[i] = -75 * kDegToRad;
    alt[i] = 1000 + 0.5 * c * t * t;
  }
  const NavTrack tr = track_from_positions(dt, lat, lon, alt, zero, zero, zero);
  for (int i = 2; i + 2 < n; ++i) {
    EXPECT_NEAR(tr.vd_mps[i], -c * i * dt, 1e-9) << i;
    EXPECT_NEAR(tr.fd_mps2[i], -c - kStandardGravity_mps2, 1e-7) << i;
    EXPECT_NEAR(tr.vn_mps[i], 50.0, 1e-3) << i;  // the metres per radian change with latitude
    EXPECT_NEAR(tr.ve_mps[i], 0.0, 1e-12) << i;
  }
  EXPECT_NEAR(tr.vd_mps[0], -(alt[1] - alt[0]) / dt, 1e-9);  // one-sided
  EXPECT_NEAR(tr.vd_mps[n - 1], -(alt[n - 1] - alt[n - 2]) / dt, 1e-9);
  EXPECT_TRUE(tr.cnb[5].isApprox(Eigen::Matrix3d::Identity(), 1e-15));

  // Sample by sample: two behind, then the flush gives the last two.
  StreamingTrack s(dt);
  size_t got = 0;
  for (int i = 0; i < n; ++i) {
    InsSample x;
    x.t_s = i * dt;
    x.lat_rad = lat[i];
    x.lon_rad = lon[i];
    x.alt_m = alt[i];
    const auto pts = s.push(x);
    got += pts.size();
    EXPECT_EQ(got, static_cast<size_t>(std::max(0, i - 1)));
  }
  const auto last = s.flush();
  ASSERT_EQ(last.size(), 2u);
  EXPECT_EQ(last[1].point.vd_mps, tr.vd_mps[n - 1]);
  EXPECT_EQ(last[1].point.fd_mps2, tr.fd_mps2[n - 1]);
}

struct Example {
  NavTrack ins;
  Eigen::VectorXd lat, lon, alt, roll, pitch, yaw, anomaly;
  AnomalyMap map;
  FilterSettings settings;
  double dt = 1.0;
};

const Example& example() {
  static const Example e = [] {
    Example x;
    const std::string dir = test::reference_dir() + "/magnav_nav/";
    const auto& col = test::simple_example_column;
    const Eigen::VectorXd tt = col("tt");
    x.dt = tt[1] - tt[0];
    x.lat = col("ins_lat") * kDegToRad;
    x.lon = col("ins_lon") * kDegToRad;
    x.alt = col("ins_alt");
    x.roll = col("ins_roll") * kDegToRad;
    x.pitch = col("ins_pitch") * kDegToRad;
    x.yaw = col("ins_yaw") * kDegToRad;
    x.ins = track_from_positions(x.dt, x.lat, x.lon, x.alt, x.roll, x.pitch, x.yaw);
    x.anomaly = col("mag_1_c");
    x.map = read_anomaly_map(dir + "simple_map.h5");
    x.settings = filter_model(x.dt, x.lat[0], ModelSigmas{});
    return x;
  }();
  return e;
}

InsSample sample(const Example& e, Eigen::Index i) {
  InsSample s;
  s.t_s = static_cast<double>(i) * e.dt;
  s.lat_rad = e.lat[i];
  s.lon_rad = e.lon[i];
  s.alt_m = e.alt[i];
  s.roll_rad = e.roll[i];
  s.pitch_rad = e.pitch[i];
  s.yaw_rad = e.yaw[i];
  return s;
}

TEST(NavStreaming, OnlineEqualsTheBatchFilterBitForBit) {
  // Measurements arrive 3 samples late (a compensator's look-ahead); sample 40's never comes and
  // a stray one (between two stamps) is ignored. The batch filter, given NaN at 40, agrees to
  // the last bit at every sample.
  const Example& e = example();
  const Eigen::Index n = e.ins.size(), lag = 3, missing = 40;
  Eigen::VectorXd z = e.anomaly;
  z[missing] = NAN;
  const FilterResult batch = run_ekf(e.ins, z, e.map, e.settings);
  StreamingNavigator nav(e.map, e.settings, e.dt);
  std::vector<NavigatorOutput> out;
  auto take = [&](std::vector<NavigatorOutput> v) { out.insert(out.end(), v.begin(), v.end()); };
  for (Eigen::Index i = 0; i < n + lag; ++i) {
    if (i < n) take(nav.push_ins(sample(e, i)));
    const Eigen::Index k = i - lag;
    if (k >= 0 && k != missing) take(nav.push_measurement(k * e.dt, e.anomaly[k], NAN));
    if (k == 10) take(nav.push_measurement((k + 0.5) * e.dt, 1e6, NAN));  // stray
  }
  take(nav.end_of_ins());
  take(nav.flush());
  ASSERT_EQ(static_cast<Eigen::Index>(out.size()), n);
  for (Eigen::Index i = 0; i < n; ++i) {
    const NavigatorOutput& o = out[static_cast<size_t>(i)];
    ASSERT_EQ(o.t_s, i * e.dt);
    ASSERT_EQ(o.lat_rad, e.ins.lat_rad[i] + batch.x(0, i)) << i;
    ASSERT_EQ(o.lon_rad, e.ins.lon_rad[i] + batch.x(1, i)) << i;
    ASSERT_EQ(o.step.updated, i != missing) << i;
    if (i != missing) {
      ASSERT_EQ(o.step.innovation_nT, batch.innovation_nT[i]) << i;
    }
    const double kn = dlat_to_north_m(1.0, o.lat_rad);
    ASSERT_NEAR(o.position_cov_ned_m2(0, 0), kn * kn * batch.p[static_cast<size_t>(i)](0, 0),
                1e-9 * o.position_cov_ned_m2(0, 0));
  }
  EXPECT_EQ(nav.counts().missing_measurements, 1);
  EXPECT_EQ(nav.counts().unmatched_measurements, 1);
  EXPECT_EQ(nav.counts().updates, n - 1);
  EXPECT_EQ(nav.pending(), 0u);
}

TEST(NavStreaming, GapsDisorderAndLeavingTheMapAreCountedNotFatal) {
  const Example& e = example();
  // A map whose cells beyond the track's middle (in latitude or longitude) are masked: the
  // filter leaves it halfway and predicts only.
  AnomalyMap small = e.map;
  const Eigen::Index rows = small.lat_rad.size(), cols = small.lon_rad.size(), n = e.ins.size();
  const double dlat = e.lat[n - 1] - e.lat[0], dlon = e.lon[n - 1] - e.lon[0];
  const bool by_lat = std::abs(dlat) > std::abs(dlon);
  const double mid = by_lat ? e.lat[n / 2] : e.lon[n / 2], dir = by_lat ? dlat : dlon;
  small.mask = Eigen::MatrixXd::Ones(rows, cols);
  for (Eigen::Index r = 0; r < rows; ++r)
    for (Eigen::Index c = 0; c < cols; ++c)
      if (((by_lat ? small.lat_rad[r] : small.lon_rad[c]) - mid) * dir > 0) small.mask(r, c) = 0;
  StreamingNavigator nav(small, e.settings, e.dt);
  std::vector<NavigatorOutput> out;
  auto take = [&](std::vector<NavigatorOutput> v) { out.insert(out.end(), v.begin(), v.end()); };
  for (Eigen::Index i = 0; i < e.ins.size(); ++i) {
    if (i >= 50 && i < 55) continue;  // a 5 s gap in the INS
    take(nav.push_ins(sample(e, i)));
    if (i == 60) take(nav.push_ins(sample(e, 59)));  // out of order
    take(nav.push_measurement(i * e.dt, e.anomaly[i], NAN));
  }
  take(nav.end_of_ins());
  take(nav.flush());
  EXPECT_EQ(static_cast<Eigen::Index>(out.size()), e.ins.size() - 5);
  EXPECT_EQ(nav.counts().gaps, 1);
  EXPECT_EQ(nav.counts().out_of_order, 1);
  EXPECT_EQ(nav.counts().unmatched_measurements, 0);
  long on = 0;
  for (const auto& o : out) {
    EXPECT_TRUE(std::isfinite(o.lat_rad) && std::isfinite(o.position_cov_ned_m2(0, 0)));
    on += o.step.on_map;
  }
  std::printf("  on the map %ld of %zu steps, off-map measurements %ld\n", on, out.size(),
              nav.counts().off_map);
  EXPECT_GT(nav.counts().off_map, 20);
  EXPECT_GT(on, 20);
  EXPECT_EQ(nav.counts().off_map + nav.counts().updates, static_cast<long>(out.size()));
}

TEST(NavStreaming, TheGateRejectsAnOutlier) {
  const Example& e = example();
  FilterSettings s = e.settings;
  s.nis_gate = 10.83;
  Eigen::VectorXd z = e.anomaly;
  z[30] += 500.0;  // 500 nT: far outside a 3 nT measurement's spread
  const FilterResult gated = run_ekf(e.ins, z, e.map, s);
  const FilterResult clean = run_ekf(e.ins, e.anomaly, e.map, s);
  EXPECT_TRUE(std::isnan(gated.innovation_nT[30]));
  EXPECT_EQ(gated.x(0, 29), clean.x(0, 29));
  s.nis_gate = INFINITY;
  const FilterResult open = run_ekf(e.ins, z, e.map, s);
  EXPECT_GT(std::abs(open.x(17, 30) - clean.x(17, 30)), 1.0);  // the outlier moved it
}

TEST(NavMap, CubicInterpolationIsExactOnQuadraticsAndPassesThroughTheGrid) {
  // Keys' cubic convolution reproduces a quadratic surface inside the grid (bilinear does not),
  // equals the grid at its nodes, and its gradient is the surface's.
  AnomalyMap m;
  const int n = 12;
  m.lat_rad = Eigen::VectorXd::LinSpaced(n, 0.700, 0.711);
  m.lon_rad = Eigen::VectorXd::LinSpaced(n, -1.300, -1.289);
  auto f = [](double la, double lo) {
    const double u = (la - 0.7) * 1e3, v = (lo + 1.3) * 1e3;
    return 3 * u * u - 2 * u * v + 0.5 * v * v + 7 * u - 4 * v + 10;
  };
  m.map_nT.resize(n, n);
  for (int i = 0; i < n; ++i)
    for (int j = 0; j < n; ++j) m.map_nT(i, j) = f(m.lat_rad[i], m.lon_rad[j]);
  const double la = 0.70537, lo = -1.29413;
  const double linear = m.value(la, lo);
  m.interpolation = AnomalyMap::Interpolation::Cubic;
  EXPECT_NEAR(m.value(la, lo), f(la, lo), 1e-9);
  EXPECT_GT(std::abs(linear - f(la, lo)), 1e-3);  // the bilinear one is not exact
  EXPECT_NEAR(m.value(m.lat_rad[4], m.lon_rad[7]), m.map_nT(4, 7), 1e-12);
  const Eigen::Vector2d g = m.gradient(la, lo);
  const double u = (la - 0.7) * 1e3, v = (lo + 1.3) * 1e3;
  EXPECT_NEAR(g[0], 1e3 * (6 * u - 2 * v + 7), 1e-3 * std::abs(g[0]) + 1e-2);
  EXPECT_NEAR(g[1], 1e3 * (-2 * u + v - 4), 1e-3 * std::abs(g[1]) + 1e-2);
}

TEST(NavStreaming, AConstantOffsetIsRemovedAtTheStart) {
  // The measurement 300 nT off the map (the aircraft's constant field a band-pass TL fit leaves):
  // with offset_from_first the filter gives the clean run's track to 5 cm (the offset is read at
  // the INS's first position, a few metres from the truth's).
  const Example& e = example();
  FilterSettings s = e.settings;
  const Eigen::VectorXd shifted = (e.anomaly.array() + 300.0).matrix();
  const FilterResult clean = run_ekf(e.ins, e.anomaly, e.map, s);
  s.offset_from_first = true;
  const FilterResult fixed = run_ekf(e.ins, shifted, e.map, s);
  const Eigen::Index last = e.ins.size() - 1;
  const double lat = e.ins.lat_rad[last];
  EXPECT_LT(std::abs(dlat_to_north_m(fixed.x(0, last) - clean.x(0, last), lat)), 0.05);
  EXPECT_LT(std::abs(dlon_to_east_m(fixed.x(1, last) - clean.x(1, last), lat)), 0.05);
  MapMatchingEkf f(e.map, s);
  f.step(e.ins.point(0), e.ins.lat_rad[0], e.ins.lon_rad[0], shifted[0], NAN, e.dt);
  EXPECT_NEAR(f.offset_nT(), shifted[0] - e.map.value(e.ins.lat_rad[0], e.ins.lon_rad[0]), 1e-9);
  s.offset_from_first = false;  // MagNav.jl's filter: the offset drags the position
  const FilterResult dragged = run_ekf(e.ins, shifted, e.map, s);
  EXPECT_GT(std::hypot(dlat_to_north_m(dragged.x(0, last) - clean.x(0, last), lat),
                       dlon_to_east_m(dragged.x(1, last) - clean.x(1, last), lat)),
            1.0);
}

}  // namespace
}  // namespace magcomp::nav

namespace magcomp {
namespace {

TEST(LocalEnu, EllipsoidPointsAndRoundTrips) {
  // WGS-84: the equator at 0 deg is at the semi-major axis, the pole at the semi-minor one.
  EXPECT_NEAR(geodetic_to_ecef(0, 0, 0).x(), 6378137.0, 1e-6);
  EXPECT_NEAR(geodetic_to_ecef(90, 0, 0).z(), 6356752.314245, 1e-5);
  const LocalEnu enu(45.3, -75.7, 0.0);
  // One arc-minute of latitude at 45.3 deg is 1852.3 m of meridian (M = a(1-e2)/(1-e2 s^2)^1.5).
  const Eigen::Vector3d north = enu.forward(45.3 + 1.0 / 60, -75.7, 0.0);
  EXPECT_NEAR(north.y(), 1852.3, 0.5);
  EXPECT_NEAR(north.x(), 0.0, 1e-6);
  for (const Eigen::Vector3d& p :
       {Eigen::Vector3d(20000, -35000, 800), Eigen::Vector3d(-5, 3, 1)}) {
    const Eigen::Vector3d g = enu.reverse(p);
    EXPECT_LT((enu.forward(g.x(), g.y(), g.z()) - p).norm(), 1e-6) << p.transpose();
  }
}

}  // namespace
}  // namespace magcomp

namespace magcomp::nav {
namespace {

TEST(NavStreaming, HostileSamplesAreRefusedAndNoOutputIsEverNan) {
  // The node's inputs at their worst: the INS at a pole, 1e300 m up, NaN attitude; a measurement
  // of 1e300 nT and one of inf; an hour's gap. Each is refused and counted; every output finite.
  const Example& e = example();
  StreamingNavigator nav(e.map, e.settings, e.dt);
  std::vector<NavigatorOutput> out;
  auto take = [&](std::vector<NavigatorOutput> v) { out.insert(out.end(), v.begin(), v.end()); };
  for (Eigen::Index i = 0; i < e.ins.size(); ++i) {
    InsSample s = sample(e, i);
    if (i == 20) s.lat_rad = 90 * kDegToRad;
    if (i == 21) s.lat_rad = -89.9 * kDegToRad;
    if (i == 22) s.alt_m = 1e300;
    if (i == 23) s.yaw_rad = NAN;
    if (i >= 70) s.t_s += 7200;  // two hours without the INS
    take(nav.push_ins(s));
    const double z = i == 30 ? 1e300 : i == 31 ? INFINITY : e.anomaly[i];
    take(nav.push_measurement(s.t_s, z, NAN));
  }
  take(nav.end_of_ins());
  take(nav.flush());
  const NavigatorCounts& c = nav.counts();
  EXPECT_EQ(c.invalid_ins, 4);
  EXPECT_EQ(c.invalid_measurements, 2);
  EXPECT_EQ(c.nan_measurements, 0);  // the refused ones are not counted twice
  EXPECT_EQ(c.filter_restarts, 1);   // the two-hour gap
  EXPECT_EQ(static_cast<Eigen::Index>(out.size()), e.ins.size() - 4);
  for (const NavigatorOutput& o : out) {
    ASSERT_TRUE(std::isfinite(o.lat_rad) && std::isfinite(o.lon_rad) && std::isfinite(o.alt_m));
    ASSERT_TRUE(o.position_cov_ned_m2.allFinite() && o.velocity_ned_mps.allFinite());
  }
  EXPECT_EQ(invalid_ins_reason(sample(e, 0)), "");
  InsSample pole = sample(e, 0);
  pole.lat_rad = 89.6 * kDegToRad;
  EXPECT_EQ(invalid_ins_reason(pole), "latitude within 0.5 deg of a pole");
}

TEST(NavStreaming, TheBoundAlongTheTruthIsTheCrlb) {
  // crlb_run (the filter on the true track measuring the map itself) gives crlb()'s covariance
  // (MagNav.jl's vectors) wherever the map covers the track.
  const Example& e = example();
  std::vector<InsSample> truth;
  for (Eigen::Index i = 0; i < e.ins.size(); ++i) truth.push_back(sample(e, i));
  const FlightRun run = crlb_run(truth, e.map, e.settings, e.dt);
  const std::vector<Eigen::MatrixXd> p = crlb(e.ins, e.map, e.settings);
  ASSERT_EQ(run.steps.size(), p.size());
  for (size_t i = 0; i < p.size(); ++i) {
    const double kn = dlat_to_north_m(1.0, e.lat[static_cast<Eigen::Index>(i)]);
    ASSERT_NEAR(run.steps[i].position_cov_ned_m2(0, 0), kn * kn * p[i](0, 0),
                1e-9 * kn * kn * p[i](0, 0))
        << i;
    ASSERT_EQ(run.rows[i], static_cast<Eigen::Index>(i));
  }
  EXPECT_EQ(run.counts.updates, e.ins.size());
}

}  // namespace
}  // namespace magcomp::nav
