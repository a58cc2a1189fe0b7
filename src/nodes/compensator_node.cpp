// magcomp compensator node: a few lines around CompensatorRos.
#include <ros/ros.h>

#include "magcomp/ros/compensator_ros.h"

int main(int argc, char** argv) {
  ros::init(argc, argv, "compensator");
  try {
    magcomp::rosio::CompensatorRos compensator(ros::NodeHandle(), ros::NodeHandle("~"));
    ros::spin();
  } catch (const std::exception& e) {
    ROS_FATAL("magcomp compensator: %s", e.what());
    return 1;
  }
  return 0;
}
