#pragma once

#include <cstdint>
#include <filesystem>
#include <optional>
#include <string>
#include <vector>

#include "densemap/geometry/error.hpp"
#include "densemap/geometry/rigid_transform.hpp"
#include "densemap/sim/sequence.hpp"

namespace densemap::load {

/// One sensor stream of a load run, after `count` is expanded.
struct SensorPlan {
  std::string sensor_id;
  std::filesystem::path data;         // a dataset, or empty with `sim` set
  std::optional<SequenceOptions> sim;  // generated into the work directory
  double rate_hz = 10;
  double start_offset_s = 0;
  Transform offset = Transform::Identity();  // applied to every pose (several robots, one map)
  std::size_t first = 0, limit = 0;
  bool loop = true;
};

enum class QueryKind { kPoint = 0, kBox = 1, kRay = 2 };
inline constexpr int kQueryKinds = 3;
[[nodiscard]] const char* queryKindName(QueryKind kind);

/// One query client (its own DDS participant), after `count` is expanded.
struct ClientPlan {
  std::string name;
  double rate_hz = 10;  // 0: closed loop
  double weights[kQueryKinds] = {1, 0, 0};
  std::size_t point_batch = 1000;
  double bbox_edge_m = 10, ray_range_m = 30, spread_m = 20;
  std::size_t around_sensor = 0;  // index into Scenario::sensors
  std::uint64_t max_requests = 10'000'000;
};

struct Slo {
  double e2e_p99_ms = 100;
  std::uint64_t max_dropped = 0;
  double query_p99_ms = 0;  // 0: not checked
  std::uint64_t max_failed_queries = 0;
};

struct RampPlan {
  bool vary_sensors = true;  // else query clients
  std::uint32_t start = 1, step = 1, max_steps = 8;
  double step_duration_s = 20;
  bool reset_between_steps = true;
};

struct SoakPlan {
  double warm_up_s = 60, max_rss_growth = 0.10, max_p99_drift = 0.20, window_s = 300,
         drift_floor_ms = 5;
};

/// A stream or client as written, before `count` copies are made of it.
struct SensorTemplate {
  SensorPlan plan;
  Transform offset_step = Transform::Identity();
  std::uint32_t count = 1;
};
struct ClientTemplate {
  ClientPlan plan;
  std::uint32_t count = 1;
};

/// `count` copies of a stream: ids ID-1 .. ID-count (ID alone when count is 1), copy i offset
/// by offset_step^i more and started i / (rate * count) s later, so copies do not fire at once.
[[nodiscard]] std::vector<SensorPlan> expandSensors(const SensorTemplate& t);
[[nodiscard]] std::vector<ClientPlan> expandClients(const ClientTemplate& t);

/// A validated load scenario (idl/densemap_load.proto) with every count expanded.
struct Scenario {
  std::string name;
  double duration_s = 30;
  double sample_period_s = 1;
  std::vector<SensorPlan> sensors;
  std::vector<ClientPlan> clients;
  std::vector<double> joiner_times_s;  // when each late joiner starts, from the run's start
  Slo slo;
  std::optional<RampPlan> ramp;
  std::optional<SoakPlan> soak;
  std::vector<SensorTemplate> sensor_templates;  // as written (the ramp copies the first)
  std::vector<ClientTemplate> client_templates;
};

inline constexpr double kMaxDurationS = 86400;  // one day: soaks included
inline constexpr std::size_t kMaxSensors = 64, kMaxClients = 256, kMaxJoiners = 1000;

/// Parses and checks a scenario (text format); errors name the field, or the line and column.
[[nodiscard]] Expected<Scenario> parseScenario(const std::string& text);
[[nodiscard]] Expected<Scenario> loadScenario(const std::filesystem::path& file);

/// Step `step` (0-based) of a ramp: the first sensor stream (or query client) repeated
/// `start + step * step`-many times, each copy shifted as `count` copies are, for the step's
/// duration; no late joiners.
[[nodiscard]] Scenario rampStep(const Scenario& base, std::uint32_t step);
/// The number of streams (or clients) a ramp step runs.
[[nodiscard]] std::uint32_t rampCount(const RampPlan& ramp, std::uint32_t step);

/// Where the dataset of a simulated stream is kept under `work_dir` (one per option set).
[[nodiscard]] std::filesystem::path simDatasetDir(const SequenceOptions& sim,
                                                  const std::filesystem::path& work_dir);

}  // namespace densemap::load
