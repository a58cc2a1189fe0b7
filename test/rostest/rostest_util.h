// magcomp rostests: what every test node shares (collecting outputs, waiting, main).
#pragma once

#include <diagnostic_msgs/DiagnosticArray.h>
#include <gtest/gtest.h>
#include <magcomp/CompensatedField.h>
#include <ros/ros.h>
#include <std_srvs/SetBool.h>

#include <atomic>
#include <chrono>
#include <condition_variable>
#include <deque>
#include <functional>
#include <limits>
#include <map>
#include <memory>
#include <mutex>
#include <random>
#include <string>
#include <thread>
#include <vector>

namespace magcomp::rostest_util {

/// Every message of type M received on `topic`, in arrival order (thread-safe).
template <typename M>
class MessageCollector {
 public:
  MessageCollector(ros::NodeHandle& nh, const std::string& topic) {
    sub_ = nh.subscribe(topic, 100000, &MessageCollector::on, this);
  }
  size_t size() const {
    std::lock_guard<std::mutex> lock(mutex_);
    return out_.size();
  }
  std::vector<M> all() const {
    std::lock_guard<std::mutex> lock(mutex_);
    return out_;
  }

 private:
  void on(const typename M::ConstPtr& m) {
    std::lock_guard<std::mutex> lock(mutex_);
    out_.push_back(*m);
  }
  mutable std::mutex mutex_;
  std::vector<M> out_;
  ros::Subscriber sub_;
};

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

/// The latest key-values of the compensator's diagnostics status (the last message wins).
class DiagnosticsCollector {
 public:
  explicit DiagnosticsCollector(ros::NodeHandle& nh, const std::string& status_name = "compensator")
      : name_(status_name) {
    sub_ = nh.subscribe("/diagnostics", 100, &DiagnosticsCollector::on, this);
  }
  /// The value of `key` as a number, -1 when not seen.
  long count(const std::string& key) const {
    std::lock_guard<std::mutex> lock(mutex_);
    auto it = values_.find(key);
    return it == values_.end() ? -1 : std::stol(it->second);
  }
  std::map<std::string, std::string> values() const {
    std::lock_guard<std::mutex> lock(mutex_);
    return values_;
  }

 private:
  void on(const diagnostic_msgs::DiagnosticArray::ConstPtr& a) {
    std::lock_guard<std::mutex> lock(mutex_);
    for (const auto& s : a->status) {
      if (s.name.find(name_) == std::string::npos) continue;
      for (const auto& kv : s.values) values_[kv.key] = kv.value;
      values_["level"] = std::to_string(static_cast<int>(s.level));
    }
  }
  std::string name_;
  mutable std::mutex mutex_;
  std::map<std::string, std::string> values_;
  ros::Subscriber sub_;
};

/// Republishes every message M of `in` on `out` after a random wall delay drawn uniformly in
/// [0, max_delay_s], keeping the topic's own order (fault injection: one late input). The output
/// is advertised first and the input subscribed only once the output has a subscriber (within
/// 20 s), so a player waiting for its subscribers starts only when nothing can be lost.
template <typename M>
class DelayRelay {
 public:
  DelayRelay(ros::NodeHandle& nh, const std::string& in, const std::string& out, double max_delay_s,
             unsigned seed)
      : max_delay_s_(max_delay_s), rng_(seed) {
    pub_ = nh.advertise<M>(out, 100000);
    const ros::WallTime t0 = ros::WallTime::now();
    while (pub_.getNumSubscribers() == 0 && (ros::WallTime::now() - t0).toSec() < 20.0) {
      ros::WallDuration(0.05).sleep();
    }
    thread_ = std::thread([this] { run(); });
    sub_ = nh.subscribe(in, 100000, &DelayRelay::on, this);
  }
  ~DelayRelay() {
    sub_.shutdown();
    {
      std::lock_guard<std::mutex> lock(mutex_);
      stop_ = true;
    }
    cv_.notify_all();
    thread_.join();
  }
  long relayed() const { return relayed_; }
  double max_delay_s() const { return max_delay_s_; }

 private:
  using Clock = std::chrono::steady_clock;
  void on(const typename M::ConstPtr& msg) {
    std::lock_guard<std::mutex> lock(mutex_);
    auto at =
        Clock::now() + std::chrono::duration_cast<Clock::duration>(std::chrono::duration<double>(
                           std::uniform_real_distribution<double>(0, max_delay_s_)(rng_)));
    if (!queue_.empty() && at < queue_.back().first) at = queue_.back().first;  // keep order
    queue_.emplace_back(at, msg);
    cv_.notify_all();
  }
  void run() {
    std::unique_lock<std::mutex> lock(mutex_);
    while (!stop_) {
      if (queue_.empty()) {
        cv_.wait(lock);
        continue;
      }
      const auto at = queue_.front().first;
      if (Clock::now() < at) {
        cv_.wait_until(lock, at);
        continue;
      }
      auto msg = queue_.front().second;
      queue_.pop_front();
      pub_.publish(msg);
      ++relayed_;
    }
  }
  double max_delay_s_;
  std::mt19937 rng_;
  ros::Subscriber sub_;
  ros::Publisher pub_;
  std::mutex mutex_;
  std::condition_variable cv_;
  std::deque<std::pair<Clock::time_point, typename M::ConstPtr>> queue_;
  bool stop_ = false;
  std::atomic<long> relayed_{0};
  std::thread thread_;
};

/// The DelayRelay of M that the test node's private parameters ask for: relay_in republished on
/// relay_out after a random wall delay of up to relay_max_delay_s (s); none without relay_in.
template <typename M>
std::unique_ptr<DelayRelay<M>> relay_from_params(ros::NodeHandle& nh, const ros::NodeHandle& pnh,
                                                 unsigned seed) {
  std::string in, out;
  double max_delay_s = 0.0;
  pnh.param<std::string>("relay_in", in, "");
  pnh.param<std::string>("relay_out", out, "");
  pnh.param("relay_max_delay_s", max_delay_s, 0.0);
  if (in.empty()) return nullptr;
  return std::make_unique<DelayRelay<M>>(nh, in, out, max_delay_s, seed);
}

/// Polls count() every poll_s (wall time) until it reaches `expected`, or it has not grown for
/// quiet_s after it first became non-zero and stream_ended() (when given) holds, or limit_s has
/// passed. Calls tick(count) after each
/// poll. Returns the last count.
inline size_t wait_until_settled(const std::function<size_t()>& count, size_t expected,
                                 double quiet_s, double limit_s, double poll_s,
                                 const std::function<void(size_t)>& tick = {},
                                 const std::function<bool()>& stream_ended = {}) {
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
    // Quiet only ends the wait once the input stream has ended: a node or player starved of
    // CPU for a while mid-flight is waited for.
    const bool ended = !stream_ended || stream_ended();
    if (!ended) last_change = ros::WallTime::now();  // quiet is counted from the stream's end
    if (ended && last > 0 && (ros::WallTime::now() - last_change).toSec() > quiet_s) break;
  }
  return last;
}

/// Under simulated time (a `rosbag play --clock` replay): true once the clock has come within
/// 1 s of `last_stamp` (the replayed flight's last sample time, s; the player publishes its
/// clock at its own rate, so the last clock it sends may fall short of the last message).
/// Without simulated time there is no clock to read the replay's progress from: true.
inline bool replay_reached(const ros::Time& last_stamp) {
  if (!ros::Time::isSimTime()) return true;
  return ros::Time::now() >= last_stamp - ros::Duration(1.0);
}

/// A player started paused (`rosbag play --pause`, node name `player`): waits until `ready()`
/// holds (the node under test is up, e.g. its output has reached the test's subscriber), then
/// `settle_s` more for its input subscriptions to connect, and starts the replay through the
/// player's `pause_playback` service. A node slow to start (libtorch, a loaded machine) then
/// misses no sample. Returns false if the node never came up within `limit_s` or the player
/// offers no such service.
inline bool start_replay_when_ready(const std::function<bool()>& ready, double limit_s,
                                    double settle_s = 1.0,
                                    const std::string& service = "/player/pause_playback") {
  const ros::WallTime start = ros::WallTime::now();
  while (!ready()) {
    if ((ros::WallTime::now() - start).toSec() > limit_s) return false;
    ros::WallDuration(0.05).sleep();
  }
  ros::WallDuration(settle_s).sleep();
  if (!ros::service::waitForService(service, ros::Duration(limit_s))) return false;
  std_srvs::SetBool play;
  play.request.data = false;  // pause = false
  return ros::service::call(service, play);
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
