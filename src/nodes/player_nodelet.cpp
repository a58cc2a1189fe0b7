// magcomp player nodelet: plays a bag inside a nodelet manager (zero-copy into the compensator).
#include <nodelet/nodelet.h>
#include <pluginlib/class_list_macros.hpp>

#include <memory>

#include "magcomp/ros/bag_player.h"

namespace magcomp::rosio {

class PlayerNodelet : public nodelet::Nodelet {
 private:
  void onInit() override {
    impl_ = std::make_unique<BagPlayer>(getNodeHandle(), getPrivateNodeHandle());
  }
  std::unique_ptr<BagPlayer> impl_;
};

}  // namespace magcomp::rosio

PLUGINLIB_EXPORT_CLASS(magcomp::rosio::PlayerNodelet, nodelet::Nodelet)
