// magcomp compensator nodelet: the same class as the node, in a nodelet manager.
#include <nodelet/nodelet.h>
#include <pluginlib/class_list_macros.hpp>

#include <memory>

#include "magcomp/ros/compensator_ros.h"

namespace magcomp::rosio {

class CompensatorNodelet : public nodelet::Nodelet {
 private:
  void onInit() override {
    impl_ = std::make_unique<CompensatorRos>(getNodeHandle(), getPrivateNodeHandle());
  }
  std::unique_ptr<CompensatorRos> impl_;
};

}  // namespace magcomp::rosio

PLUGINLIB_EXPORT_CLASS(magcomp::rosio::CompensatorNodelet, nodelet::Nodelet)
