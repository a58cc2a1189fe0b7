// magcomp navigator nodelet: the same class as the node, in a nodelet manager.
#include <nodelet/nodelet.h>
#include <ros/callback_queue.h>

#include <atomic>
#include <memory>
#include <pluginlib/class_list_macros.hpp>
#include <thread>

#include "magcomp/ros/navigator_ros.h"

namespace magcomp::rosio {

/// Runs NavigatorRos on its own callback queue and thread rather than the manager's worker pool:
/// the pool hands every message from a manager thread to a worker (two wake-ups per message),
/// which at a bag played as fast as possible cost more than the compensation itself. One thread
/// keeps the callbacks serialised, as in the node.
class NavigatorNodelet : public nodelet::Nodelet {
 public:
  ~NavigatorNodelet() override {
    running_ = false;
    queue_.disable();
    if (thread_.joinable()) thread_.join();
    impl_.reset();  // its subscriptions go before the queue they use
  }

 private:
  void onInit() override {
    ros::NodeHandle nh = getNodeHandle(), pnh = getPrivateNodeHandle();
    nh.setCallbackQueue(&queue_);
    pnh.setCallbackQueue(&queue_);
    impl_ = std::make_unique<NavigatorRos>(nh, pnh);
    thread_ = std::thread([this] {
      while (running_ && ros::ok()) queue_.callAvailable(ros::WallDuration(0.1));
    });
  }
  ros::CallbackQueue queue_;
  std::unique_ptr<NavigatorRos> impl_;
  std::atomic<bool> running_{true};
  std::thread thread_;
};

}  // namespace magcomp::rosio

PLUGINLIB_EXPORT_CLASS(magcomp::rosio::NavigatorNodelet, nodelet::Nodelet)
