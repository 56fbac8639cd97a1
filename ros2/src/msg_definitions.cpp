#include "densemap/ros2/msg_definitions.hpp"

#include <initializer_list>
#include <utility>

namespace densemap::ros2 {
namespace {

std::string withDependencies(const std::string& main,
                             std::initializer_list<std::pair<const char*, const char*>> deps) {
  const std::string rule(80, '=');
  std::string s = main;
  for (const auto& [name, text] : deps) s += rule + "\nMSG: " + name + "\n" + text;
  return s;
}

const char* kHeaderMsg = "builtin_interfaces/Time stamp\nstring frame_id\n";
const char* kTimeMsg = "int32 sec\nuint32 nanosec\n";
const char* kVector3Msg = "float64 x\nfloat64 y\nfloat64 z\n";
const char* kQuaternionMsg = "float64 x 0\nfloat64 y 0\nfloat64 z 0\nfloat64 w 1\n";

}  // namespace

const std::string& pointCloud2Definition() {
  static const std::string s = withDependencies(
      "std_msgs/Header header\nuint32 height\nuint32 width\nPointField[] fields\nbool "
      "is_bigendian\nuint32 point_step\nuint32 row_step\nuint8[] data\nbool is_dense\n",
      {{"std_msgs/Header", kHeaderMsg},
       {"builtin_interfaces/Time", kTimeMsg},
       {"sensor_msgs/PointField",
        "uint8 INT8 = 1\nuint8 UINT8 = 2\nuint8 INT16 = 3\nuint8 UINT16 = 4\nuint8 INT32 = "
        "5\nuint8 UINT32 = 6\nuint8 FLOAT32 = 7\nuint8 FLOAT64 = 8\nstring name\nuint32 "
        "offset\nuint8 datatype\nuint32 count\n"}});
  return s;
}

const std::string& tfMessageDefinition() {
  static const std::string s =
      withDependencies("geometry_msgs/TransformStamped[] transforms\n",
                       {{"geometry_msgs/TransformStamped",
                         "std_msgs/Header header\nstring child_frame_id\nTransform transform\n"},
                        {"std_msgs/Header", kHeaderMsg},
                        {"builtin_interfaces/Time", kTimeMsg},
                        {"geometry_msgs/Transform", "Vector3 translation\nQuaternion rotation\n"},
                        {"geometry_msgs/Vector3", kVector3Msg},
                        {"geometry_msgs/Quaternion", kQuaternionMsg}});
  return s;
}

const std::string& occupancyGridDefinition() {
  static const std::string s = withDependencies(
      "std_msgs/Header header\nMapMetaData info\nint8[] data\n",
      {{"std_msgs/Header", kHeaderMsg},
       {"builtin_interfaces/Time", kTimeMsg},
       {"nav_msgs/MapMetaData",
        "builtin_interfaces/Time map_load_time\nfloat32 resolution\nuint32 width\nuint32 "
        "height\ngeometry_msgs/Pose origin\n"},
       {"geometry_msgs/Pose", "Point position\nQuaternion orientation\n"},
       {"geometry_msgs/Point", kVector3Msg},
       {"geometry_msgs/Quaternion", kQuaternionMsg}});
  return s;
}

}  // namespace densemap::ros2
