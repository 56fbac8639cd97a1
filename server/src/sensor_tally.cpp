#include "densemap/server/sensor_tally.hpp"

#include "densemap/geometry/percentile.hpp"

namespace densemap::server {

SensorCounters& SensorTally::at(const std::string& sensor_id) { return sensor(sensor_id).counters; }

SensorTally::Sensor& SensorTally::sensor(const std::string& sensor_id) {
  auto it = by_id_.find(sensor_id);
  if (it != by_id_.end()) return it->second;
  const std::string& id = by_id_.size() < kMaxSensors ? sensor_id : std::string(kOtherSensors);
  Sensor& s = by_id_[id];
  s.counters.sensor_id = id;
  return s;
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

void SensorTally::integrated(const std::string& sensor_id, double latency_ms) {
  Sensor& s = sensor(sensor_id);
  ++s.counters.integrated;
  if (s.latencies.size() < kLatencyWindow) {
    s.latencies.push_back(latency_ms);
  } else {
    s.latencies[s.next] = latency_ms;
    s.next = (s.next + 1) % kLatencyWindow;
  }
}

std::vector<SensorCounters> SensorTally::sensors() const {
  std::vector<SensorCounters> out;
  out.reserve(by_id_.size());
  for (const auto& [id, s] : by_id_) {
    SensorCounters c = s.counters;
    if (!s.latencies.empty()) {
      c.latency_p50_ms = percentile(s.latencies, 0.5);
      c.latency_p99_ms = percentile(s.latencies, 0.99);
    }
    out.push_back(std::move(c));
  }
  return out;
}

}  // namespace densemap::server
