// magcomp calibrator nodelet: the same class as the node, in a nodelet manager.
#include <nodelet/nodelet.h>

#include <memory>
#include <pluginlib/class_list_macros.hpp>

#include "magcomp/ros/calibrator_ros.h"

namespace magcomp::rosio {

class CalibratorNodelet : public nodelet::Nodelet {
 private:
  void onInit() override {
    impl_ = std::make_unique<CalibratorRos>(getNodeHandle(), getPrivateNodeHandle());
  }
  std::unique_ptr<CalibratorRos> impl_;
};

}  // namespace magcomp::rosio

PLUGINLIB_EXPORT_CLASS(magcomp::rosio::CalibratorNodelet, nodelet::Nodelet)
