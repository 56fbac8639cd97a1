#pragma once

#include <cstdint>
#include <map>
#include <string>
#include <vector>

namespace densemap {

/// What the pipeline did with one sensor's scans.
struct SensorCounters {
  std::string sensor_id;
  std::uint64_t received = 0;    // submitted to the pipeline
  std::uint64_t integrated = 0;  // in the map
  std::uint64_t dropped = 0;     // overwritten in the latest-wins queue (integration behind)
  std::uint64_t rejected = 0;    // failed validation
  /// Sequence numbers skipped between consecutive received scans: scans lost before the
  /// pipeline saw them (e.g. overwritten in the DDS reader's history) or never sent.
  std::uint64_t seq_gaps = 0;
  std::uint64_t last_seq = 0;
};

/// Per-sensor counters of the pipeline. At most kMaxSensors ids are kept apart; scans of
/// further ids are counted under kOtherSensors, so bogus ids cannot grow it without bound.
/// Thread-safety: none (the pipeline guards it with its counters mutex).
class SensorTally {
 public:
  static constexpr std::size_t kMaxSensors = 64;
  static constexpr const char* kOtherSensors = "(other sensors)";

  void received(const std::string& sensor_id, std::uint64_t seq);
  void integrated(const std::string& sensor_id) { ++at(sensor_id).integrated; }
  void dropped(const std::string& sensor_id) { ++at(sensor_id).dropped; }
  void rejected(const std::string& sensor_id) { ++at(sensor_id).rejected; }
  /// Every sensor seen, by id.
  [[nodiscard]] std::vector<SensorCounters> sensors() const;

 private:
  SensorCounters& at(const std::string& sensor_id);
  std::map<std::string, SensorCounters> by_id_;
};

}  // namespace densemap
