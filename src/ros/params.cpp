// magcomp ROS layer: private-parameter checks shared by the nodes.
#include "magcomp/ros/params.h"

#include <ros/console.h>
#include <ros/param.h>

#include <cmath>
#include <vector>

#include "magcomp/core/error.h"

namespace magcomp::rosio {

void warn_unknown_params(const ros::NodeHandle& pnh, const std::set<std::string>& known) {
  std::vector<std::string> names;
  ros::param::getParamNames(names);
  const std::string ns = pnh.getNamespace() + "/";
  for (const auto& n : names) {
    if (n.rfind(ns, 0) != 0) continue;
    const std::string key = n.substr(ns.size());
    if (key.find('/') == std::string::npos && !known.count(key)) {
      ROS_WARN("%s: unknown parameter '%s' ignored", ns.c_str(), key.c_str());
    }
  }
}

void require_positive(double value, const std::string& key) {
  if (!(value > 0) || !std::isfinite(value)) {
    reject_param(key, "must be > 0 and finite, got " + std::to_string(value));
  }
}

void reject_param(const std::string& key, const std::string& why) {
  ROS_FATAL("~%s: %s", key.c_str(), why.c_str());
  throw Error("~" + key + ": " + why);
}

}  // namespace magcomp::rosio
