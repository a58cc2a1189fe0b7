// magcomp compensator nodelet: the same class as the node, in a nodelet manager, on its own
// callback queue and thread (own_thread_nodelet.h).
#include <pluginlib/class_list_macros.hpp>

#include "magcomp/ros/compensator_ros.h"
#include "own_thread_nodelet.h"

namespace magcomp::rosio {
class CompensatorNodelet : public OwnThreadNodelet<CompensatorRos> {};
}  // namespace magcomp::rosio

PLUGINLIB_EXPORT_CLASS(magcomp::rosio::CompensatorNodelet, nodelet::Nodelet)
