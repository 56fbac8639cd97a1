#pragma once

// The ROS 2 message definitions (`ros2msg`: the type's .msg text, then each dependency after a
// line of '=' as `MSG: pkg/Type` and its text) of the types densemap writes in CDR: what MCAP
// bags store as a schema and what a Foxglove `cdr` channel advertises.
#include <string>

namespace densemap::ros2 {

[[nodiscard]] const std::string& pointCloud2Definition();    // sensor_msgs/msg/PointCloud2
[[nodiscard]] const std::string& tfMessageDefinition();      // tf2_msgs/msg/TFMessage
[[nodiscard]] const std::string& occupancyGridDefinition();  // nav_msgs/msg/OccupancyGrid

}  // namespace densemap::ros2
