// magcomp navigator nodelet: the same class as the node, in a nodelet manager, on its own
// callback queue and thread (own_thread_nodelet.h).
#include <pluginlib/class_list_macros.hpp>

#include "magcomp/ros/navigator_ros.h"
#include "own_thread_nodelet.h"

namespace magcomp::rosio {
class NavigatorNodelet : public OwnThreadNodelet<NavigatorRos> {};
}  // namespace magcomp::rosio

PLUGINLIB_EXPORT_CLASS(magcomp::rosio::NavigatorNodelet, nodelet::Nodelet)
