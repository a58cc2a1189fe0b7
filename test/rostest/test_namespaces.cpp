// rostest: two compensators under two namespaces on one master, each fed its own flight. Each
// output is its own flight's offline compensation sample for sample (the flights share their
// stamps, so any mixing of the inputs would show), and no magcomp topic is left in the root
// namespace.
#include <gtest/gtest.h>
#include <magcomp/CompensatedField.h>
#include <ros/ros.h>

#include <cmath>
#include <memory>

#include "magcomp/core/apply/apply.h"
#include "magcomp/core/model/model.h"
#include "rostest_util.h"

namespace {

double rms_difference(const std::vector<magcomp::CompensatedField>& online,
                      const Eigen::VectorXd& offline, long* compared) {
  double ss = 0;
  *compared = 0;
  for (size_t i = 0; i < online.size() && static_cast<Eigen::Index>(i) < offline.size(); ++i) {
    const double a = online[i].compensated_nT, b = offline[static_cast<Eigen::Index>(i)];
    if (!std::isfinite(a) || !std::isfinite(b)) continue;
    ss += (a - b) * (a - b);
    ++*compared;
  }
  return *compared ? std::sqrt(ss / static_cast<double>(*compared)) : NAN;
}

TEST(Namespaces, EachAircraftPublishesOnlyItsOwnFlight) {
  ros::NodeHandle nh, pnh("~");
  std::string model_path;
  std::vector<std::string> namespaces, flights;
  ASSERT_TRUE(pnh.getParam("model", model_path));
  ASSERT_TRUE(pnh.getParam("namespaces", namespaces));
  ASSERT_TRUE(pnh.getParam("flights", flights));
  ASSERT_EQ(namespaces.size(), 2u);
  ASSERT_EQ(flights.size(), 2u);
  const magcomp::Model model = magcomp::load_model_yaml(model_path);
  std::vector<Eigen::VectorXd> offline;
  std::vector<std::unique_ptr<magcomp::rostest_util::OutputCollector>> collectors;
  size_t expected = 0;
  for (size_t k = 0; k < 2; ++k) {
    const magcomp::FlightData f = magcomp::read_flight_h5(flights[k]);
    offline.push_back(magcomp::compensate(model, f));
    expected += static_cast<size_t>(f.size());
    collectors.push_back(std::make_unique<magcomp::rostest_util::OutputCollector>(
        nh, "/" + namespaces[k] + "/magcomp/compensated"));
  }
  // The two flights differ: an output fed the other aircraft's inputs could not pass.
  long n_between = 0;
  std::vector<magcomp::CompensatedField> as_online(static_cast<size_t>(offline[1].size()));
  for (Eigen::Index i = 0; i < offline[1].size(); ++i)
    as_online[static_cast<size_t>(i)].compensated_nT = offline[1][i];
  const double between = rms_difference(as_online, offline[0], &n_between);
  std::printf("  the two flights' offline compensations differ by %.3f nT rms\n", between);
  ASSERT_GT(between, 1.0);

  magcomp::rostest_util::wait_until_settled(
      [&] { return collectors[0]->size() + collectors[1]->size(); }, expected, 10.0, 200.0, 0.2);
  for (size_t k = 0; k < 2; ++k) {
    const auto out = collectors[k]->outputs();
    long compared = 0;
    const double rms = rms_difference(out, offline[k], &compared);
    std::printf("  %s: %zu outputs for %ld samples; online vs its own offline: rms %.3e nT\n",
                namespaces[k].c_str(), out.size(), static_cast<long>(offline[k].size()), rms);
    EXPECT_EQ(out.size(), static_cast<size_t>(offline[k].size())) << namespaces[k];
    EXPECT_GT(compared, offline[k].size() - 10) << namespaces[k];
    EXPECT_LT(rms, 1e-6) << namespaces[k];
  }
  // Nothing of magcomp's is advertised in the root namespace.
  ros::master::V_TopicInfo topics;
  ASSERT_TRUE(ros::master::getTopics(topics));
  for (const auto& t : topics) {
    EXPECT_NE(t.name.rfind("/magcomp/", 0), 0u) << "published outside the namespaces: " << t.name;
  }
}

}  // namespace

int main(int argc, char** argv) {
  return magcomp::rostest_util::run_tests(argc, argv, "test_namespaces", 1);
}
