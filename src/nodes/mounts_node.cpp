// magcomp mounts node: broadcasts the sensor mounts of config/sensor_mounts.yaml as static tf2
// transforms from base_link, once (latched).
#include <geometry_msgs/TransformStamped.h>
#include <ros/ros.h>
#include <tf2/LinearMath/Quaternion.h>
#include <tf2_ros/static_transform_broadcaster.h>

#include <vector>

int main(int argc, char** argv) {
  ros::init(argc, argv, "mounts");
  ros::NodeHandle pnh("~");
  std::string parent;
  pnh.param<std::string>("parent_frame", parent, "base_link");
  XmlRpc::XmlRpcValue mounts;
  if (!pnh.getParam("mounts", mounts) || mounts.getType() != XmlRpc::XmlRpcValue::TypeStruct) {
    ROS_FATAL(
        "~mounts: required map frame -> {xyz_m: [x, y, z], rpy_rad: [r, p, y]} "
        "(config/sensor_mounts.yaml)");
    return 1;
  }
  std::vector<geometry_msgs::TransformStamped> transforms;
  for (auto& [frame, m] : mounts) {
    auto vec3 = [&, frame = frame](const char* key, bool required) {
      std::vector<double> v(3, 0.0);
      if (!m.hasMember(key)) {
        if (required) throw std::runtime_error("~mounts/" + frame + "/" + key + ": missing");
        return v;
      }
      XmlRpc::XmlRpcValue& x = m[key];
      if (x.getType() != XmlRpc::XmlRpcValue::TypeArray || x.size() != 3) {
        throw std::runtime_error("~mounts/" + frame + "/" + key + ": must be a list of 3 numbers");
      }
      for (int i = 0; i < 3; ++i) {
        v[static_cast<size_t>(i)] = x[i].getType() == XmlRpc::XmlRpcValue::TypeInt
                                        ? static_cast<int>(x[i])
                                        : static_cast<double>(x[i]);
      }
      return v;
    };
    try {
      const auto xyz = vec3("xyz_m", true), rpy = vec3("rpy_rad", false);
      geometry_msgs::TransformStamped t;
      t.header.stamp = ros::Time(0);
      t.header.frame_id = parent;
      t.child_frame_id = frame;
      t.transform.translation.x = xyz[0];
      t.transform.translation.y = xyz[1];
      t.transform.translation.z = xyz[2];
      tf2::Quaternion q;
      q.setRPY(rpy[0], rpy[1], rpy[2]);
      t.transform.rotation.x = q.x();
      t.transform.rotation.y = q.y();
      t.transform.rotation.z = q.z();
      t.transform.rotation.w = q.w();
      transforms.push_back(t);
    } catch (const std::exception& e) {
      ROS_FATAL("%s", e.what());
      return 1;
    }
  }
  tf2_ros::StaticTransformBroadcaster broadcaster;
  broadcaster.sendTransform(transforms);
  ROS_INFO("magcomp mounts: %zu static transforms from %s", transforms.size(), parent.c_str());
  ros::spin();
  return 0;
}
