// rostest: the calibrator's batch fit over a replayed flight equals `magcomp calibrate`; its
// recursive solution converges toward it.
#include <gtest/gtest.h>
#include <magcomp/CalibrationStatus.h>
#include <ros/ros.h>
#include <std_srvs/Trigger.h>

#include <cstdio>
#include <mutex>

#include "magcomp/core/evaluate/evaluation.h"
#include "rostest_util.h"

namespace {

std::mutex g_mutex;
magcomp::CalibrationStatus g_status;
bool g_have = false;

void on_status(const magcomp::CalibrationStatus::ConstPtr& m) {
  std::lock_guard<std::mutex> lock(g_mutex);
  g_status = *m;
  g_have = true;
}

TEST(Calibrator, BatchEqualsCliAndRecursiveConverges) {
  ros::NodeHandle nh, pnh("~");
  std::string h5, cli_path, saved;
  ASSERT_TRUE(pnh.getParam("h5", h5));
  ASSERT_TRUE(pnh.getParam("cli_model", cli_path));
  ASSERT_TRUE(pnh.getParam("saved", saved));
  bool automatic = false;  // segments detected from the rates: compare quality, not coefficients
  pnh.param("auto", automatic, false);
  std::remove(saved.c_str());
  ros::Subscriber sub = nh.subscribe("/calibrator/calibration_status", 10, on_status);
  // Wait until the replay is over: the collected sample count stops growing.
  magcomp::rostest_util::wait_until_settled(
      [] {
        std::lock_guard<std::mutex> lock(g_mutex);
        return g_have ? static_cast<size_t>(g_status.samples) : size_t{0};
      },
      std::numeric_limits<size_t>::max(), 4.0, 200.0, 0.5);
  magcomp::CalibrationStatus rls;
  {
    std::lock_guard<std::mutex> lock(g_mutex);
    ASSERT_TRUE(g_have);
    rls = g_status;
  }
  EXPECT_EQ(rls.state, "collecting");
  if (automatic) {
    EXPECT_GE(rls.segments, 4u);
  } else {
    EXPECT_EQ(rls.segments, 4u);  // the box's four legs
  }
  std_srvs::Trigger fit, save;
  ASSERT_TRUE(ros::service::call("/calibrator/fit", fit));
  ASSERT_TRUE(fit.response.success) << fit.response.message;
  ASSERT_TRUE(ros::service::call("/calibrator/save", save));
  ASSERT_TRUE(save.response.success) << save.response.message;
  const magcomp::Model online = magcomp::load_model_yaml(saved);
  const magcomp::Model cli = magcomp::load_model_yaml(cli_path);
  ASSERT_EQ(online.coefficients.size(), cli.coefficients.size());
  double worst = 0;
  for (Eigen::Index j = 0; j < cli.coefficients.size(); ++j) {
    worst = std::max(worst, std::abs(online.coefficients[j] - cli.coefficients[j]) /
                                std::max(std::abs(cli.coefficients[j]), 1e-9));
  }
  const magcomp::FlightData f = magcomp::read_flight_h5(h5);
  magcomp::Model rls_model = cli;
  ASSERT_EQ(rls.coefficients.size(), static_cast<size_t>(cli.coefficients.size()));
  rls_model.coefficients =
      Eigen::Map<const Eigen::VectorXd>(rls.coefficients.data(), cli.coefficients.size());
  const double batch_std = magcomp::evaluate_model(online, f, "mag_1_c").std_nT;
  const double rls_std = magcomp::evaluate_model(rls_model, f, "mag_1_c").std_nT;
  std::printf(
      "  batch vs calibrate: worst relative difference %.2e; error std: batch %.3f nT, "
      "recursive %.3f nT (%u samples in %u segments)\n",
      worst, batch_std, rls_std, rls.samples, rls.segments);
  if (automatic) {
    const double cli_std = magcomp::evaluate_model(cli, f, "mag_1_c").std_nT;
    std::printf("  automatic segments: batch %.3f nT vs calibrate on the known lines %.3f nT\n",
                batch_std, cli_std);
    EXPECT_LT(batch_std, 1.3 * cli_std);
  } else {
    EXPECT_LT(worst, 1e-9);
  }
  EXPECT_LT(rls_std, 3.0 * batch_std);
}

}  // namespace

int main(int argc, char** argv) {
  return magcomp::rostest_util::run_tests(argc, argv, "test_calibrate", 1);
}
