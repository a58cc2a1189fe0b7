// magcomp calibrator node: a few lines around CalibratorRos.
#include <ros/ros.h>

#include "magcomp/ros/calibrator_ros.h"

int main(int argc, char** argv) {
  ros::init(argc, argv, "calibrator");
  try {
    magcomp::rosio::CalibratorRos calibrator(ros::NodeHandle(), ros::NodeHandle("~"));
    ros::spin();
  } catch (const std::exception& e) {
    ROS_FATAL("magcomp calibrator: %s", e.what());
    return 1;
  }
  return 0;
}
