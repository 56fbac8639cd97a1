#pragma once

#include <filesystem>
#include <string>
#include <vector>

#include "densemap/load/runner.hpp"

namespace densemap::load {

struct LatencyStats {
  std::size_t n = 0;
  double p50 = 0, p99 = 0, p999 = 0, max = 0;
};
/// Nearest-rank percentiles of the `ms` of `samples`.
[[nodiscard]] LatencyStats latencyStats(const std::vector<Timed>& samples);

/// Server and machine CPU over a stretch of samples, in percent of one core (server, this tool)
/// and of the whole machine (busy).
struct CpuUse {
  double server_pct = 0, load_pct = 0, machine_busy_pct = 0;
};
[[nodiscard]] CpuUse cpuUse(const std::vector<UsageSample>& usage, double from_s, double to_s);

/// One bin of the timeline (JSON and PNG).
struct TimelineBin {
  double t_s = 0;
  LatencyStats e2e;          // scans sent in this bin, every sensor
  double scans_per_s = 0;    // integrated and seen
  double queries_per_s = 0;  // answered, every kind
  LatencyStats query;        // every kind
  CpuUse cpu;
  double server_rss_mib = 0;
  std::uint64_t dropped = 0;  // scans dropped or rejected by the server since the start
};
[[nodiscard]] std::vector<TimelineBin> timeline(const RunResult& run, double period_s);

/// What a run must keep (Scenario::slo); `broken` says what failed, empty when kept.
struct SloVerdict {
  bool kept = true;
  std::string broken;
  LatencyStats e2e, query;
  std::uint64_t dropped = 0, failed_queries = 0;
};
[[nodiscard]] SloVerdict checkSlo(const RunResult& run, const Slo& slo);

/// Soak verdict, the first window after warm-up against the last: growth of the server's peak
/// RSS and drift of the end-to-end p99.
struct SoakVerdict {
  bool passed = true;
  std::string why;
  double rss_at_warm_up_mib = 0, rss_max_after_mib = 0;  // peaks in the first / last window
  double rss_growth = 0;
  LatencyStats first_window, last_window;
  double p99_drift = 0;
};
[[nodiscard]] SoakVerdict checkSoak(const RunResult& run, const SoakPlan& soak);
/// The soak's verdict as a gate: the trend (above) and the scenario's SLO over the whole run
/// (drops, rejections, e2e and query p99, failed queries).
[[nodiscard]] SoakVerdict checkSoak(const RunResult& run, const SoakPlan& soak, const Slo& slo);

/// The timeline as a table (soak reports: one row per sample period).
[[nodiscard]] std::string timelineTable(const RunResult& run, const Scenario& scenario);
[[nodiscard]] std::string soakSummary(const SoakVerdict& verdict);

/// Markdown tables: per sensor stream, per query client and kind, late joiners, server usage.
[[nodiscard]] std::string tables(const RunResult& run);

/// One ramp step's outcome.
struct RampStepResult {
  std::uint32_t count = 0;  // sensors or clients in this step
  SloVerdict slo;
  CpuUse cpu;
  double scans_per_s = 0, queries_per_s = 0;
};
[[nodiscard]] std::string rampTable(const std::vector<RampStepResult>& steps, bool vary_sensors);
/// Where the ramp broke and what was saturated at the first step that broke the SLO.
[[nodiscard]] std::string kneeSummary(const std::vector<RampStepResult>& steps, bool vary_sensors,
                                      const Slo& slo);

/// JSON with the summary, per-stream counts and the timeline.
[[nodiscard]] Expected<void> writeJson(const std::filesystem::path& file, const RunResult& run,
                                       const Scenario& scenario);
[[nodiscard]] Expected<void> writeRampJson(const std::filesystem::path& file,
                                           const std::vector<RampStepResult>& steps,
                                           const Scenario& scenario);

/// PNG over time: end-to-end and query latency, scans and queries per second, CPU, RSS.
[[nodiscard]] Expected<void> writeRunChart(const std::filesystem::path& file, const RunResult& run,
                                           const Scenario& scenario);
/// PNG over the ramp's steps: latency, throughput and CPU against the number of streams.
[[nodiscard]] Expected<void> writeRampChart(const std::filesystem::path& file,
                                            const std::vector<RampStepResult>& steps,
                                            const Scenario& scenario);

}  // namespace densemap::load
