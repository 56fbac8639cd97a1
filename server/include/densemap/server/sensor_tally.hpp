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
  static constexpr std::size_t kLatencyWindow = 256;

  void received(const std::string& sensor_id, std::uint64_t seq);
  /// An integrated scan and its received -> published latency.
  void integrated(const std::string& sensor_id, double latency_ms);
  void dropped(const std::string& sensor_id) { ++at(sensor_id).dropped; }
  void rejected(const std::string& sensor_id) { ++at(sensor_id).rejected; }
  /// Every sensor seen, by id, with the latency percentiles of its last kLatencyWindow scans.
  [[nodiscard]] std::vector<SensorCounters> sensors() const;

 private:
  struct Sensor {
    SensorCounters counters;
    std::vector<double> latencies;  // a ring of the last kLatencyWindow
    std::size_t next = 0;
  };
  Sensor& sensor(const std::string& sensor_id);
  SensorCounters& at(const std::string& sensor_id);
  std::map<std::string, Sensor> by_id_;
};

}  // namespace densemap::server
