#pragma once

#include <Eigen/Geometry>

#include <array>
#include <string>
#include <string_view>

#include "densemap/io/scan.hpp"

namespace densemap::ros2 {

/// The DDS topic rmw_cyclonedds uses for a ROS 2 topic: "rt" + the fully qualified name
/// ("/points" and "points" -> "rt/points"). Errors (empty string) for an empty name, a name
/// ending in '/', or characters ROS does not allow (letters, digits, '_' and '/' only).
[[nodiscard]] std::string ddsTopicName(std::string_view ros_name);
/// `name` resolved in the namespace `ns` as a ROS name is ("/robot1" and "/points" or "points"
/// -> "/robot1/points"; an empty or "/" namespace leaves "/points"). Empty when either is not a
/// valid ROS name (ddsTopicName's rules).
[[nodiscard]] std::string inNamespace(std::string_view ns, std::string_view name);
/// Whether `name` matches the glob `pattern`: '*' stands for any run of characters, '?' for one.
[[nodiscard]] bool matchesGlob(std::string_view pattern, std::string_view name);
/// The namespace of a cloud topic's DDS name: "rt/robot1/points" with `cloud` "/points" (or
/// "points") -> "/robot1"; empty unless the topic is `cloud` under a namespace.
[[nodiscard]] std::string namespaceOfCloud(std::string_view dds_topic, std::string_view cloud);
/// Whether `name` is a valid ROS 2 node name (rcl's rules: letters, digits and '_', not
/// empty, not starting with a digit; at most 255 characters, rmw_dds_common's bound 256).
[[nodiscard]] bool isNodeName(std::string_view name);

/// A RawScan's pose and its conversions (densemap/io/scan.hpp).
using densemap::fromScanPose;
using densemap::ScanPose;
using densemap::toScanPose;

}  // namespace densemap::ros2
