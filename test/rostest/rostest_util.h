// magcomp rostests: what every test node shares (collecting outputs, waiting, main).
#pragma once

#include <gtest/gtest.h>
#include <magcomp/CompensatedField.h>
#include <ros/ros.h>

#include <functional>
#include <limits>
#include <mutex>
#include <string>
#include <vector>

namespace magcomp::rostest_util {

/// Collects every magcomp/CompensatedField published on a topic, in arrival order.
class OutputCollector {
 public:
  explicit OutputCollector(ros::NodeHandle& nh, const std::string& topic = "/magcomp/compensated") {
    sub_ = nh.subscribe(topic, 100000, &OutputCollector::on, this);
  }
  size_t size() const {
    std::lock_guard<std::mutex> lock(mutex_);
    return out_.size();
  }
  std::vector<magcomp::CompensatedField> outputs() const {
    std::lock_guard<std::mutex> lock(mutex_);
    return out_;
  }
  const ros::Subscriber& subscriber() const { return sub_; }

 private:
  void on(const magcomp::CompensatedField::ConstPtr& m) {
    std::lock_guard<std::mutex> lock(mutex_);
    out_.push_back(*m);
  }
  mutable std::mutex mutex_;
  std::vector<magcomp::CompensatedField> out_;
  ros::Subscriber sub_;
};

/// Polls count() every poll_s (wall time) until it reaches `expected`, or it has not grown for
/// quiet_s after it first became non-zero, or limit_s has passed. Calls tick(count) after each
/// poll. Returns the last count.
inline size_t wait_until_settled(const std::function<size_t()>& count, size_t expected,
                                 double quiet_s, double limit_s, double poll_s,
                                 const std::function<void(size_t)>& tick = {}) {
  const ros::WallTime start = ros::WallTime::now();
  size_t last = 0;
  ros::WallTime last_change = start;
  while ((ros::WallTime::now() - start).toSec() < limit_s) {
    ros::WallDuration(poll_s).sleep();
    const size_t n = count();
    if (tick) tick(n);
    if (n != last) {
      last = n;
      last_change = ros::WallTime::now();
    }
    if (last >= expected) break;
    if (last > 0 && (ros::WallTime::now() - last_change).toSec() > quiet_s) break;
  }
  return last;
}

/// The test node's main: gtest, ros::init and an asynchronous spinner for the subscriptions.
inline int run_tests(int argc, char** argv, const char* node_name, int spinner_threads) {
  testing::InitGoogleTest(&argc, argv);
  ros::init(argc, argv, node_name);
  ros::AsyncSpinner spinner(spinner_threads);
  spinner.start();
  return RUN_ALL_TESTS();
}

}  // namespace magcomp::rostest_util
