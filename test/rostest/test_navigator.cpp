// rostest: the navigator fed by the replayed flight (player -> compensator -> navigator, one
// nodelet manager) reproduces the offline navigation (`magcomp navigate`'s filter on the
// offline compensation) at every INS sample, and its diagnostics account for every sample.
#include <gtest/gtest.h>
#include <magcomp/NavigationStatus.h>
#include <ros/ros.h>
#include <sensor_msgs/NavSatFix.h>

#include <Eigen/Geometry>
#include <cmath>
#include <mutex>

#include "magcomp/core/math/constants.h"
#include "magcomp/core/model/model.h"
#include "magcomp/core/nav/flight_navigation.h"
#include "magcomp/core/nav/nav_model.h"
#include "magcomp/core/geo/attitude.h"
#include "rostest_util.h"

namespace {

template <typename M>
using Collector = magcomp::rostest_util::MessageCollector<M>;

TEST(Navigator, ReplayedFlightEqualsOfflineNavigation) {
  using namespace magcomp;
  ros::NodeHandle nh, pnh("~");
  std::string h5, model_path, map_path;
  double tol_m = 1e-3;
  ASSERT_TRUE(pnh.getParam("h5", h5));
  ASSERT_TRUE(pnh.getParam("model", model_path));
  ASSERT_TRUE(pnh.getParam("map", map_path));
  pnh.param("tolerance_m", tol_m, 1e-6);
  Collector<sensor_msgs::NavSatFix> fixes(nh, "/magcomp/nav/fix");
  Collector<magcomp::NavigationStatus> status(nh, "/magcomp/nav/status");
  rostest_util::DiagnosticsCollector diagnostics(nh, "navigator");

  // Offline: what `magcomp navigate --model` runs (its default settings), on the map as stored
  // (the node's map_altitude_m is not set; navigate continues the map to the flight's mean
  // altitude when it lies above it).
  const FlightData f = read_flight_h5(h5);
  const nav::FlightTracks tracks = nav::flight_tracks(f);
  const Eigen::VectorXd z = nav::measured_anomaly_nT(f, load_model_yaml(model_path));
  const nav::AnomalyMap map = nav::read_anomaly_map(map_path);
  nav::FilterSettings s = nav::filter_model(f.dt_s(), tracks.ins.lat_rad[0], nav::ModelSigmas{});
  s.offset_from_first = true;
  s.map_representation_var = true;  // the node's and navigate's default
  const nav::FilterResult cli = nav::run_ekf(tracks.ins, z, map, s);
  const size_t n = static_cast<size_t>(f.size());
  rostest_util::wait_until_settled([&] { return fixes.size(); }, n, 10.0, 240.0, 0.2);
  ros::WallDuration(1.5).sleep();  // one more diagnostics period after the last output
  const auto got = fixes.all();
  const auto st = status.all();
  ASSERT_EQ(got.size(), n) << "the navigator must step every INS sample";
  ASSERT_EQ(st.size(), n);
  Eigen::VectorXd z_online(f.size());
  for (size_t i = 0; i < n; ++i) z_online[static_cast<Eigen::Index>(i)] = st[i].measurement_nT;
  // The core on the values the messages carried: the INS position in degrees (NavSatFix), its
  // attitude as an ENU quaternion (Imu), converted back as the navigator does, and the anomaly
  // the compensator published (equal to the offline one to ~1e-10 nT: online_offline.test). The
  // node must equal the core on these to the last bits.
  const Eigen::Index n_ins = f.size();
  Eigen::VectorXd lat(n_ins), lon(n_ins), roll(n_ins), pitch(n_ins), yaw(n_ins);
  const auto ins_lat = f.column("ins_lat"), ins_lon = f.column("ins_lon");
  const auto r = f.column("ins_roll"), p = f.column("ins_pitch"), y = f.column("ins_yaw");
  for (Eigen::Index i = 0; i < n_ins; ++i) {
    lat[i] = ins_lat[i] * kRadToDeg * kDegToRad;
    lon[i] = ins_lon[i] * kRadToDeg * kDegToRad;
    const Eigen::Quaterniond q =
        enu_orientation(r[i] * kDegToRad, p[i] * kDegToRad, y[i] * kDegToRad);
    const Eigen::Vector3d a =
        ned_attitude(Eigen::Quaterniond(q.w(), q.x(), q.y(), q.z()).normalized());
    roll[i] = a.x();
    pitch[i] = a.y();
    yaw[i] = a.z();
  }
  // The node steps at 1 / rate_hz; the file's step is the median of its stamps' differences.
  double rate_hz = 10.0;
  pnh.param("rate_hz", rate_hz, 10.0);
  const double dt = 1.0 / rate_hz;
  std::printf("  the file's step differs from 1 / rate_hz by %.3g s\n", f.dt_s() - dt);
  const nav::NavTrack ins =
      nav::track_from_positions(dt, lat, lon, f.column("ins_alt"), roll, pitch, yaw);
  nav::FilterSettings s_node = nav::filter_model(dt, ins.lat_rad[0], nav::ModelSigmas{});
  s_node.offset_from_first = true;
  s_node.map_representation_var = true;
  const nav::FilterResult offline = nav::run_ekf(ins, z_online, map, s_node);
  const double drms_offline =
      nav::position_errors(ins, offline.x, tracks.truth.lat_rad, tracks.truth.lon_rad).drms_m;
  const double drms_cli =
      nav::position_errors(tracks.ins, cli.x, tracks.truth.lat_rad, tracks.truth.lon_rad).drms_m;

  double worst_m = 0.0, worst_cli_m = 0.0, ss = 0.0;
  long used = 0;
  for (size_t i = 0; i < n; ++i) {
    const auto k = static_cast<Eigen::Index>(i);
    if (i > 0) {
      ASSERT_GT(got[i].header.stamp, got[i - 1].header.stamp) << i;
    }
    const double lat = got[i].latitude * kDegToRad, lon = got[i].longitude * kDegToRad;
    const double dn = nav::dlat_to_north_m(lat - (ins.lat_rad[k] + offline.x(0, k)), lat);
    const double de = nav::dlon_to_east_m(lon - (ins.lon_rad[k] + offline.x(1, k)), lat);
    worst_cli_m =
        std::max(worst_cli_m,
                 std::hypot(nav::dlat_to_north_m(lat - (tracks.ins.lat_rad[k] + cli.x(0, k)), lat),
                            nav::dlon_to_east_m(lon - (tracks.ins.lon_rad[k] + cli.x(1, k)), lat)));
    worst_m = std::max(worst_m, std::hypot(dn, de));
    const double tl = tracks.truth.lat_rad[k];  // position_errors' convention
    const double en = nav::dlat_to_north_m(lat - tl, tl);
    const double ee = nav::dlon_to_east_m(lon - tracks.truth.lon_rad[k], tl);
    ss += en * en + ee * ee;
    used += st[i].measurement_used;
  }
  const double drms_online = std::sqrt(ss / static_cast<double>(n));
  std::printf(
      "  %zu steps, %ld measurements used; online - offline at most %.3g m; DRMS online "
      "%.3f m, offline %.3f m\n",
      n, used, worst_m, drms_online, drms_offline);
  // The whole chain against magcomp navigate on the file: the last bits of the conversions and
  // of the online compensation, amplified where the bilinear map's gradient jumps at a cell
  // edge, stay far below the navigation error itself.
  std::printf("  the core on the file: DRMS %.3f m, at most %.3g m from the node\n", drms_cli,
              worst_cli_m);
  for (const char* k : {"steps", "updates", "missing_measurements", "off_map_measurements",
                        "unmatched_measurements_dropped", "ins_gaps", "out_of_order_dropped"})
    std::printf("  diagnostics %s = %ld\n", k, diagnostics.count(k));
  EXPECT_LT(worst_m, tol_m);
  EXPECT_NEAR(drms_online, drms_offline, tol_m);
  EXPECT_LT(worst_cli_m, 1e-2 * drms_cli);
  EXPECT_EQ(diagnostics.count("steps"), static_cast<long>(n));
  EXPECT_EQ(diagnostics.count("ins_gaps"), 0);
  EXPECT_EQ(diagnostics.count("out_of_order_dropped"), 0);
  EXPECT_EQ(diagnostics.count("updates") + diagnostics.count("missing_measurements") +
                diagnostics.count("off_map_measurements") +
                diagnostics.count("gated_measurements") + diagnostics.count("nan_measurements"),
            static_cast<long>(n));
}

}  // namespace

int main(int argc, char** argv) {
  return magcomp::rostest_util::run_tests(argc, argv, "test_navigator", 2);
}
