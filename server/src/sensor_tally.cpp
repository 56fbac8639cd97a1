#include "densemap/server/sensor_tally.hpp"

namespace densemap::server {

SensorCounters& SensorTally::at(const std::string& sensor_id) {
  auto it = by_id_.find(sensor_id);
  if (it != by_id_.end()) return it->second;
  const std::string& id = by_id_.size() < kMaxSensors ? sensor_id : std::string(kOtherSensors);
  SensorCounters& c = by_id_[id];
  c.sensor_id = id;
  return c;
}

void SensorTally::received(const std::string& sensor_id, std::uint64_t seq) {
  SensorCounters& c = at(sensor_id);
  ++c.received;
  // Gaps only within one sensor's increasing sequence (from its second scan on); a smaller
  // seq is a restart or reorder, and the "other sensors" bucket has no common sequence.
  if (c.received > 1 && c.sensor_id != kOtherSensors && seq > c.last_seq + 1) {
    c.seq_gaps += seq - c.last_seq - 1;
  }
  c.last_seq = seq;
}

std::vector<SensorCounters> SensorTally::sensors() const {
  std::vector<SensorCounters> out;
  out.reserve(by_id_.size());
  for (const auto& [id, c] : by_id_) out.push_back(c);
  return out;
}

}  // namespace densemap::server
