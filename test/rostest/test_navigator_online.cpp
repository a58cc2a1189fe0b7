// rostest: online calibration in the stack (player -> compensator -> navigator, one manager).
// The navigator, learning the coefficients from cold, equals the core's filter run on the values
// its messages carried (the INS as NavSatFix and Imu, the raw anomaly and the columns as the
// compensator published them) at every INS sample, position and coefficients; ~save_model
// writes the coefficients it holds.
#include <gtest/gtest.h>
#include <magcomp/AuxChannels.h>
#include <magcomp/CompensatedField.h>
#include <ros/ros.h>
#include <sensor_msgs/NavSatFix.h>
#include <std_srvs/Trigger.h>

#include <cmath>
#include <map>
#include <mutex>

#include "magcomp/core/math/constants.h"
#include "magcomp/core/model/model.h"
#include "magcomp/core/nav/flight_navigation.h"
#include "magcomp/core/nav/flight_run.h"
#include "magcomp/core/nav/nav_model.h"
#include "magcomp/core/nav/online_calibration.h"
#include "magcomp/core/geo/attitude.h"
#include "rostest_util.h"

namespace {

template <typename M>
using Collector = magcomp::rostest_util::MessageCollector<M>;

TEST(NavigatorOnline, LearnsAsTheCoreDoesAndSavesWhatItLearned) {
  using namespace magcomp;
  ros::NodeHandle nh, pnh("~");
  std::string h5, model_path, map_path, learned_path;
  ASSERT_TRUE(pnh.getParam("h5", h5));
  ASSERT_TRUE(pnh.getParam("model", model_path));
  ASSERT_TRUE(pnh.getParam("map", map_path));
  ASSERT_TRUE(pnh.getParam("learned", learned_path));
  Collector<sensor_msgs::NavSatFix> fixes(nh, "/magcomp/nav/fix");
  Collector<magcomp::CompensatedField> fields(nh, "/magcomp/compensated");
  Collector<magcomp::AuxChannels> columns(nh, "/magcomp/compensated/columns");
  Collector<magcomp::AuxChannels> learned(nh, "/magcomp/nav/coefficients");
  const FlightData f = read_flight_h5(h5);
  const size_t n = static_cast<size_t>(f.size());
  rostest_util::wait_until_settled([&] { return fixes.size(); }, n, 10.0, 240.0, 0.2);
  ros::WallDuration(1.0).sleep();
  const auto got = fixes.all();
  ASSERT_EQ(got.size(), n) << "the navigator must step every INS sample";
  // The measurements as the messages carried them, by stamp.
  std::map<double, std::pair<double, Eigen::VectorXd>> meas;
  for (const auto& c : columns.all())
    meas[c.header.stamp.toSec()].second = Eigen::Map<const Eigen::VectorXd>(
        c.values.data(), static_cast<Eigen::Index>(c.values.size()));
  for (const auto& m : fields.all())
    meas[m.header.stamp.toSec()].first = m.anomaly_nT + m.aircraft_correction_nT;
  // The INS as the messages carried it (degrees, an ENU quaternion), stamped as the player did.
  const Model model = load_model_yaml(model_path);
  const Eigen::Index k = static_cast<Eigen::Index>(model.make_column_names().size());
  std::vector<nav::InsSample> ins;
  Eigen::VectorXd z = Eigen::VectorXd::Constant(f.size(), NAN);
  Eigen::MatrixXd a = Eigen::MatrixXd::Constant(f.size(), k, NAN);
  const auto lat = f.column("ins_lat"), lon = f.column("ins_lon"), alt = f.column("ins_alt");
  const auto r = f.column("ins_roll"), p = f.column("ins_pitch"), y = f.column("ins_yaw");
  for (size_t i = 0; i < n; ++i) {
    const auto j = static_cast<Eigen::Index>(i);
    nav::InsSample s;
    s.t_s = got[i].header.stamp.toSec();
    s.lat_rad = lat[j] * kRadToDeg * kDegToRad;
    s.lon_rad = lon[j] * kRadToDeg * kDegToRad;
    s.alt_m = alt[j];
    const Eigen::Quaterniond q =
        enu_orientation(r[j] * kDegToRad, p[j] * kDegToRad, y[j] * kDegToRad);
    const Eigen::Vector3d att =
        ned_attitude(Eigen::Quaterniond(q.w(), q.x(), q.y(), q.z()).normalized());
    s.roll_rad = att.x();
    s.pitch_rad = att.y();
    s.yaw_rad = att.z();
    ins.push_back(s);
    const auto it = meas.find(s.t_s);
    if (it != meas.end() && it->second.second.size() == k) {
      z[j] = it->second.first;
      a.row(j) = it->second.second.transpose();
    }
  }
  const nav::AnomalyMap map = nav::read_anomaly_map(map_path);
  const double dt = 0.1;
  nav::FilterSettings s = nav::filter_model(dt, ins[0].lat_rad, nav::ModelSigmas{});
  s.offset_from_first = true;
  s.map_representation_var = true;  // the node's and navigate's default
  nav::CoefficientPriorSettings ps;
  ps.cold = true;
  nav::set_coefficient_prior(model, &model, ps, &s);
  const nav::FlightRun run = nav::run_flight(ins, z, nullptr, map, s, dt, &a);
  ASSERT_EQ(run.steps.size(), n);
  double worst_m = 0;
  for (size_t i = 0; i < n; ++i) {
    const double la = got[i].latitude * kDegToRad, lo = got[i].longitude * kDegToRad;
    worst_m = std::max(worst_m, std::hypot(nav::dlat_to_north_m(la - run.steps[i].lat_rad, la),
                                           nav::dlon_to_east_m(lo - run.steps[i].lon_rad, la)));
  }
  const auto coef = learned.all();
  ASSERT_FALSE(coef.empty());
  const Eigen::VectorXd node_c = Eigen::Map<const Eigen::VectorXd>(
      coef.back().values.data(), static_cast<Eigen::Index>(coef.back().values.size()));
  const Eigen::VectorXd core_c = run.steps.back().coefficients;
  const double worst_c = (node_c - core_c).cwiseAbs().maxCoeff();
  std::printf("  %zu steps: node - core at most %.3g m; coefficients at most %.3g apart\n", n,
              worst_m, worst_c);
  EXPECT_LT(worst_m, 1e-6);
  EXPECT_LT(worst_c, 1e-6 * (1 + core_c.cwiseAbs().maxCoeff()));
  // ~save_model writes what the navigator holds.
  ros::ServiceClient save = nh.serviceClient<std_srvs::Trigger>("/navigator/save_model");
  ASSERT_TRUE(save.waitForExistence(ros::Duration(10)));
  std_srvs::Trigger call;
  ASSERT_TRUE(save.call(call));
  EXPECT_TRUE(call.response.success) << call.response.message;
  const Model saved = load_model_yaml(learned_path);
  EXPECT_LT((saved.coefficients - core_c).cwiseAbs().maxCoeff(),
            1e-6 * (1 + core_c.cwiseAbs().maxCoeff()));
  EXPECT_EQ(saved.terms, model.terms);
}

}  // namespace

int main(int argc, char** argv) {
  return magcomp::rostest_util::run_tests(argc, argv, "test_navigator_online", 2);
}
