// magcomp ROS layer: what every node does with its private parameters.
#pragma once

#include <ros/node_handle.h>

#include <set>
#include <string>

namespace magcomp::rosio {

/// Warns (ROS_WARN, one line each) about every private parameter of pnh that is not in `known`:
/// a typo is not silently ignored. Nested keys (with a '/') are left alone.
void warn_unknown_params(const ros::NodeHandle& pnh, const std::set<std::string>& known);

/// Fails start-up: ROS_FATAL and throws magcomp::Error, both "~key: why".
[[noreturn]] void reject_param(const std::string& key, const std::string& why);

/// Rejects a value that is not > 0 and finite (s, Hz, ...).
void require_positive(double value, const std::string& key);

}  // namespace magcomp::rosio
