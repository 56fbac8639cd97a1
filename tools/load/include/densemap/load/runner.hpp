#pragma once

#include <chrono>
#include <cstdint>
#include <filesystem>
#include <string>
#include <vector>

#include "densemap/client/client.hpp"
#include "densemap/load/scenario.hpp"

namespace densemap::load {

using Clock = std::chrono::steady_clock;

/// A measurement at `t_s` seconds after the run's start.
struct Timed {
  double t_s = 0;
  double ms = 0;
};

struct SensorResult {
  std::string sensor_id;
  std::uint64_t sent = 0;
  std::uint64_t seen = 0;        // scans whose map event this tool saw
  std::uint64_t late_sends = 0;  // sends more than a period behind schedule (sender slow)
  SensorCounters server;         // the server's counts for this id during the run
  std::vector<Timed> e2e;        // publish -> map event seen
};

struct QueryResult {
  std::string name;
  std::uint64_t answered[kQueryKinds] = {};
  std::uint64_t failed[kQueryKinds] = {};  // errors, timeouts included
  std::uint64_t timeouts[kQueryKinds] = {};
  std::vector<Timed> latency[kQueryKinds];  // round trip of each answered request
  std::uint64_t late_ticks = 0;             // target-rate ticks skipped because a reply was slow
  double cpu_s = 0;                         // its process's CPU (with --processes)
  std::string last_error;
  bool started = true;  // false: its process never ran its queries (no DDS participant, ...)
};

struct JoinerResult {
  double at_s = 0;     // started
  double seconds = 0;  // connect + fetch the whole map
  std::uint64_t cells = 0, version = 0;
  std::uint64_t versions_behind = 0;  // the newest version seen when it finished minus its own
  std::string error;                  // empty when it got the map
};

/// The server's status and the machine's CPU, sampled about once a second.
struct UsageSample {
  double t_s = 0;
  double server_cpu_s = 0;
  std::uint64_t server_rss = 0, known_cells = 0, map_version = 0, map_bytes = 0;
  std::uint64_t integrated = 0, dropped = 0, rejected = 0;
  double load_cpu_s = 0;  // this tool (and its client processes)
  double machine_busy_s = 0, machine_total_s = 0;
};

struct RunResult {
  std::string scenario;
  double duration_s = 0;
  std::vector<SensorResult> sensors;
  std::vector<QueryResult> clients;
  std::vector<JoinerResult> joiners;
  std::vector<UsageSample> usage;
  ServerStatus before, after;
};

struct RunOptions {
  ClientOptions client;  // domain, interface (loopback unless configured), request timeout
  std::filesystem::path work_dir = "/tmp/densemap-load";  // simulated datasets, child files
  /// Query clients as child processes (`self_exe load --child-client ...`) instead of threads.
  bool processes = false;
  std::filesystem::path self_exe;
  std::vector<std::string> child_args;  // what a child needs to rebuild the same scenario
  bool progress = true;                 // a line on stderr every few seconds
};

/// Runs a scenario against a running densemap-server and returns what every stream measured.
/// Bounded: it ends `duration_s` after its start plus at most a few seconds of draining.
[[nodiscard]] Expected<RunResult> runScenario(const Scenario& scenario, const RunOptions& options);

/// The body of one query client in its own process (--processes): runs `scenario.clients[index]`
/// from `epoch` (steady clock, shared by the processes of a machine) around the sensor tracks
/// the parent wrote to `tracks_file`, and writes its results to `out`. Returns an exit code.
int runChildClient(const Scenario& scenario, std::size_t index, Clock::time_point epoch,
                   const std::filesystem::path& tracks_file, const std::filesystem::path& out,
                   const RunOptions& options);

/// Opens every sensor's dataset (generating simulated ones under work_dir when missing).
[[nodiscard]] Expected<void> prepareData(const Scenario& scenario,
                                         const std::filesystem::path& work_dir);

}  // namespace densemap::load
