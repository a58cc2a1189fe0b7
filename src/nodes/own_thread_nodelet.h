// magcomp nodelets: a node class run in a nodelet manager on its own callback queue and thread.
#pragma once

#include <nodelet/nodelet.h>
#include <ros/callback_queue.h>
#include <ros/console.h>

#include <atomic>
#include <exception>
#include <memory>
#include <thread>

namespace magcomp::rosio {

/// Runs Impl (constructed from the node and private handles) on its own callback queue and
/// thread rather than the manager's worker pool: the pool hands every message from a manager
/// thread to a worker (two wake-ups per message), which at a bag played as fast as possible cost
/// more than the work itself. One thread keeps the callbacks serialised, as in the node.
template <class Impl>
class OwnThreadNodelet : public nodelet::Nodelet {
 public:
  ~OwnThreadNodelet() override {
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
    impl_ = std::make_unique<Impl>(nh, pnh);
    thread_ = std::thread([this] {
      while (running_ && ros::ok()) {
        // The last net under the class's own guards: nothing a callback throws ends this
        // thread, and so nothing takes the manager down.
        try {
          queue_.callAvailable(ros::WallDuration(0.1));
        } catch (const std::exception& e) {
          ROS_ERROR_THROTTLE(5.0, "magcomp nodelet: %s (message dropped)", e.what());
        }
      }
    });
  }
  ros::CallbackQueue queue_;
  std::unique_ptr<Impl> impl_;
  std::atomic<bool> running_{true};
  std::thread thread_;
};

}  // namespace magcomp::rosio
