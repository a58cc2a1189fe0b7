// magcomp navigator node: a few lines around NavigatorRos.
#include <ros/ros.h>

#include "magcomp/ros/navigator_ros.h"

int main(int argc, char** argv) {
  ros::init(argc, argv, "navigator");
  try {
    magcomp::rosio::NavigatorRos navigator(ros::NodeHandle(), ros::NodeHandle("~"));
    ros::spin();
  } catch (const std::exception& e) {
    ROS_FATAL("magcomp navigator: %s", e.what());
    return 1;
  }
  return 0;
}
