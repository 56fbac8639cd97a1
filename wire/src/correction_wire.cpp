#include "densemap/wire/correction_wire.hpp"

#include <string>
#include <vector>

#include "densemap_msgs.h"

namespace densemap::dds {

Expected<void> writePoseCorrection(const Entity& writer, const PoseCorrection& correction) {
  if (correction.poses.size() > kMaxCorrectedPoses) {
    return makeError("a pose correction carries at most " + std::to_string(kMaxCorrectedPoses) +
                     " poses, not " + std::to_string(correction.poses.size()));
  }
  std::vector<densemap_msgs_CorrectedPose> poses(correction.poses.size());
  for (std::size_t i = 0; i < poses.size(); ++i) {
    const CorrectedPose& p = correction.poses[i];
    poses[i].stamp_ns = p.stamp_ns;
    for (int k = 0; k < 3; ++k) poses[i].T_world_sensor.t[k] = p.t[k];
    for (int k = 0; k < 4; ++k) poses[i].T_world_sensor.q[k] = p.q[k];
  }
  densemap_msgs_PoseCorrection msg{};
  // Lent for the write: DDS serialises the sample and never writes through these.
  msg.sensor_id = const_cast<char*>(correction.sensor_id.c_str());
  msg.poses = borrowSequence<dds_sequence_densemap_msgs_CorrectedPose>(poses);
  return write(writer, &msg);
}

Expected<PoseCorrection> correctionFromWire(const densemap_msgs_PoseCorrection& msg) {
  if (msg.poses._length > kMaxCorrectedPoses) {
    return makeError("pose correction of " + std::to_string(msg.poses._length) +
                     " poses, more than " + std::to_string(kMaxCorrectedPoses));
  }
  PoseCorrection out;
  out.sensor_id = text(msg.sensor_id);
  out.poses.resize(msg.poses._length);
  for (std::uint32_t i = 0; i < msg.poses._length; ++i) {
    const densemap_msgs_CorrectedPose& p = msg.poses._buffer[i];
    out.poses[i].stamp_ns = p.stamp_ns;
    for (int k = 0; k < 3; ++k) out.poses[i].t[k] = p.T_world_sensor.t[k];
    for (int k = 0; k < 4; ++k) out.poses[i].q[k] = p.T_world_sensor.q[k];
  }
  return out;
}

}  // namespace densemap::dds
