#pragma once

#include <cstdint>
#include <map>
#include <string>
#include <vector>

#include "densemap/wire/server_status.hpp"

namespace densemap::server {

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

}  // namespace densemap::server
