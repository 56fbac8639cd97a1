#include "densemap/load/report.hpp"

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <fstream>
#include <sstream>
#include <thread>

#include "densemap/geometry/percentile.hpp"
#include "densemap/load/chart.hpp"

namespace densemap::load {
namespace {

std::string format(const char* fmt, auto... args) {
  char buf[512];
  std::snprintf(buf, sizeof buf, fmt, args...);
  return buf;
}

unsigned long long ull(std::uint64_t v) { return static_cast<unsigned long long>(v); }

std::vector<Timed> allE2e(const RunResult& run) {
  std::vector<Timed> all;
  for (const auto& s : run.sensors) all.insert(all.end(), s.e2e.begin(), s.e2e.end());
  return all;
}

std::vector<Timed> allQueries(const RunResult& run) {
  std::vector<Timed> all;
  for (const auto& c : run.clients) {
    for (const auto& l : c.latency) all.insert(all.end(), l.begin(), l.end());
  }
  return all;
}

std::vector<Timed> between(const std::vector<Timed>& v, double from_s, double to_s) {
  std::vector<Timed> out;
  for (const Timed& t : v) {
    if (t.t_s >= from_s && t.t_s < to_s) out.push_back(t);
  }
  return out;
}

std::uint64_t lostScans(const SensorResult& s) {
  return s.server.dropped + s.server.rejected +
         (s.sent > s.server.received ? s.sent - s.server.received : 0);
}

/// A minimal JSON writer: objects and arrays opened and closed in order, commas handled.
}  // namespace

LatencyStats latencyStats(const std::vector<Timed>& samples) {
  LatencyStats s;
  s.n = samples.size();
  if (samples.empty()) return s;
  std::vector<double> v;
  v.reserve(samples.size());
  for (const Timed& t : samples) v.push_back(t.ms);
  std::sort(v.begin(), v.end());
  s.p50 = nearestRank(v, 0.5);
  s.p99 = nearestRank(v, 0.99);
  s.p999 = nearestRank(v, 0.999);
  s.max = v.back();
  return s;
}

CpuUse cpuUse(const std::vector<UsageSample>& usage, double from_s, double to_s) {
  CpuUse c;
  if (usage.size() < 2) return c;
  std::size_t a = 0, b = usage.size() - 1;
  for (std::size_t i = 0; i < usage.size(); ++i) {
    if (usage[i].t_s <= from_s) a = i;
  }
  for (std::size_t i = usage.size(); i-- > 0;) {
    if (usage[i].t_s >= to_s) b = i;
  }
  if (b <= a) b = std::min(a + 1, usage.size() - 1);
  if (b <= a) return c;
  const UsageSample &x = usage[a], &y = usage[b];
  const double dt = y.t_s - x.t_s;
  if (dt <= 0) return c;
  c.server_pct = 100.0 * (y.server_cpu_s - x.server_cpu_s) / dt;
  c.load_pct = 100.0 * (y.load_cpu_s - x.load_cpu_s) / dt;
  const double total = y.machine_total_s - x.machine_total_s;
  if (total > 0) c.machine_busy_pct = 100.0 * (y.machine_busy_s - x.machine_busy_s) / total;
  return c;
}

std::vector<TimelineBin> timeline(const RunResult& run, double period_s) {
  std::vector<TimelineBin> bins;
  const auto e2e = allE2e(run);
  const auto queries = allQueries(run);
  for (double t = 0; t < run.duration_s - 1e-9; t += period_s) {
    TimelineBin b;
    b.t_s = t;
    const auto e = between(e2e, t, t + period_s);
    const auto q = between(queries, t, t + period_s);
    b.e2e = latencyStats(e);
    b.query = latencyStats(q);
    b.scans_per_s = static_cast<double>(e.size()) / period_s;
    b.queries_per_s = static_cast<double>(q.size()) / period_s;
    b.cpu = cpuUse(run.usage, t, t + period_s);
    const std::uint64_t lost_before = run.before.dropped + run.before.rejected;
    for (const UsageSample& u : run.usage) {
      if (u.t_s >= t + period_s) break;
      b.server_rss_mib = static_cast<double>(u.server_rss) / 1048576.0;
      const std::uint64_t lost = u.dropped + u.rejected;
      if (u.server_rss > 0) b.dropped = lost > lost_before ? lost - lost_before : 0;
    }
    bins.push_back(b);
  }
  return bins;
}

SloVerdict checkSlo(const RunResult& run, const Slo& slo) {
  SloVerdict v;
  v.e2e = latencyStats(allE2e(run));
  v.query = latencyStats(allQueries(run));
  std::uint64_t sent = 0;
  for (const auto& s : run.sensors) v.dropped += lostScans(s), sent += s.sent;
  std::uint64_t not_started = 0;
  for (const auto& c : run.clients) {
    for (const auto f : c.failed) v.failed_queries += f;
    not_started += c.started ? 0 : 1;
  }
  std::vector<std::string> broken;
  if (not_started > 0) {
    broken.push_back(format("%llu query clients failed to start", ull(not_started)));
  }
  if (sent > 0 && v.e2e.n == 0) broken.push_back("no scan reached the map");
  if (v.e2e.p99 > slo.e2e_p99_ms) {
    broken.push_back(format("e2e p99 %.1f ms > %.0f ms", v.e2e.p99, slo.e2e_p99_ms));
  }
  if (v.dropped > slo.max_dropped) {
    broken.push_back(
        format("%llu scans dropped or rejected > %llu", ull(v.dropped), ull(slo.max_dropped)));
  }
  if (slo.query_p99_ms > 0 && v.query.p99 > slo.query_p99_ms) {
    broken.push_back(format("query p99 %.1f ms > %.0f ms", v.query.p99, slo.query_p99_ms));
  }
  if (v.failed_queries > slo.max_failed_queries) {
    broken.push_back(
        format("%llu queries failed > %llu", ull(v.failed_queries), ull(slo.max_failed_queries)));
  }
  for (const auto& b : broken) v.broken += (v.broken.empty() ? "" : "; ") + b;
  v.kept = broken.empty();
  return v;
}

SoakVerdict checkSoak(const RunResult& run, const SoakPlan& soak) {
  SoakVerdict v;
  // Two windows after the warm-up: the first and the last `window_s`, or halves if shorter.
  // RSS is compared peak to peak: a daemon's RSS saws up and down as snapshots and tiles are
  // built and handed back; a leak raises the peaks.
  const double span = run.duration_s - soak.warm_up_s;
  const double window = std::min(soak.window_s, span / 2);
  const double first_from = soak.warm_up_s, first_to = soak.warm_up_s + window;
  const double last_from = run.duration_s - window, last_to = run.duration_s + 1;
  for (const UsageSample& u : run.usage) {
    const double mib = static_cast<double>(u.server_rss) / 1048576.0;
    if (u.server_rss == 0) continue;
    if (u.t_s >= first_from && u.t_s < first_to) {
      v.rss_at_warm_up_mib = std::max(v.rss_at_warm_up_mib, mib);
    }
    if (u.t_s >= last_from && u.t_s < last_to) {
      v.rss_max_after_mib = std::max(v.rss_max_after_mib, mib);
    }
  }
  if (span <= 0 || v.rss_at_warm_up_mib == 0 || v.rss_max_after_mib == 0) {
    v.passed = false;
    v.why = "no server status in a window after the warm-up (is warm_up_s shorter than the run?)";
    return v;
  }
  v.rss_growth = v.rss_max_after_mib / v.rss_at_warm_up_mib - 1.0;
  const auto e2e = allE2e(run);
  v.first_window = latencyStats(between(e2e, first_from, first_to));
  v.last_window = latencyStats(between(e2e, last_from, last_to));
  v.p99_drift = v.first_window.p99 > 0 ? v.last_window.p99 / v.first_window.p99 - 1.0 : 0.0;
  std::vector<std::string> why;
  if (v.rss_growth > soak.max_rss_growth) {
    why.push_back(format("server RSS peak grew %.1f%% (%.0f -> %.0f MiB) > %.0f%%",
                         100 * v.rss_growth, v.rss_at_warm_up_mib, v.rss_max_after_mib,
                         100 * soak.max_rss_growth));
  }
  if (v.p99_drift > soak.max_p99_drift &&
      v.last_window.p99 - v.first_window.p99 > soak.drift_floor_ms) {
    why.push_back(format("e2e p99 drifted %.1f%% (%.1f -> %.1f ms) > %.0f%%", 100 * v.p99_drift,
                         v.first_window.p99, v.last_window.p99, 100 * soak.max_p99_drift));
  }
  if (v.first_window.n == 0 || v.last_window.n == 0) why.push_back("no scans in a window");
  for (const auto& w : why) v.why += (v.why.empty() ? "" : "; ") + w;
  v.passed = why.empty();
  return v;
}

SoakVerdict checkSoak(const RunResult& run, const SoakPlan& soak, const Slo& slo) {
  SoakVerdict v = checkSoak(run, soak);
  // A trend that holds is not enough: a soak that drops scans or breaks the SLO in a window
  // (a bad first window makes any later one look like an improvement) fails too.
  if (const SloVerdict s = checkSlo(run, slo); !s.kept) {
    v.why += (v.why.empty() ? "" : "; ") + std::string("SLO broken: ") + s.broken;
    v.passed = false;
  }
  return v;
}

std::string tables(const RunResult& run) {
  std::string out;
  out +=
      "| sensor stream | sent | received | integrated | dropped | rejected | seq gaps | "
      "late sends | e2e p50 ms | p99 | p99.9 | max "
      "|\n|---|---|---|---|---|---|---|---|---|---|---|---|\n";
  for (const auto& s : run.sensors) {
    const auto l = latencyStats(s.e2e);
    out += format(
        "| %s | %llu | %llu | %llu | %llu | %llu | %llu | %llu | %.1f | %.1f | %.1f | %.1f |\n",
        s.sensor_id.c_str(), ull(s.sent), ull(s.server.received), ull(s.server.integrated),
        ull(s.server.dropped), ull(s.server.rejected), ull(s.server.seq_gaps), ull(s.late_sends),
        l.p50, l.p99, l.p999, l.max);
  }
  if (!run.clients.empty()) {
    out +=
        "\n| query client | kind | answered | failed | timeouts | per s | p50 ms | p99 | p99.9 | "
        "max |\n|---|---|---|---|---|---|---|---|---|---|\n";
    std::vector<Timed> all[kQueryKinds];
    std::uint64_t answered[kQueryKinds] = {}, failed[kQueryKinds] = {}, timeouts[kQueryKinds] = {};
    auto row = [&](const std::string& name, int k, std::uint64_t a, std::uint64_t f,
                   std::uint64_t t, const std::vector<Timed>& lat) {
      const auto l = latencyStats(lat);
      out += format("| %s | %s | %llu | %llu | %llu | %.1f | %.1f | %.1f | %.1f | %.1f |\n",
                    name.c_str(), queryKindName(static_cast<QueryKind>(k)), ull(a), ull(f), ull(t),
                    static_cast<double>(a) / run.duration_s, l.p50, l.p99, l.p999, l.max);
    };
    for (const auto& c : run.clients) {
      for (int k = 0; k < kQueryKinds; ++k) {
        if (c.answered[k] + c.failed[k] == 0) continue;
        if (run.clients.size() <= 16) {
          row(c.name, k, c.answered[k], c.failed[k], c.timeouts[k], c.latency[k]);
        }
        all[k].insert(all[k].end(), c.latency[k].begin(), c.latency[k].end());
        answered[k] += c.answered[k], failed[k] += c.failed[k], timeouts[k] += c.timeouts[k];
      }
    }
    for (int k = 0; k < kQueryKinds; ++k) {
      if (answered[k] + failed[k] > 0) {
        row("all " + std::to_string(run.clients.size()) + " clients", k, answered[k], failed[k],
            timeouts[k], all[k]);
      }
    }
  }
  if (!run.joiners.empty()) {
    out +=
        "\n| late joiner | at s | seconds to map | cells | version | versions behind | error |\n"
        "|---|---|---|---|---|---|---|\n";
    for (std::size_t i = 0; i < run.joiners.size(); ++i) {
      const auto& j = run.joiners[i];
      out += format("| %zu | %.1f | %.2f | %llu | %llu | %llu | %s |\n", i + 1, j.at_s, j.seconds,
                    ull(j.cells), ull(j.version), ull(j.versions_behind),
                    j.error.empty() ? "-" : j.error.c_str());
    }
  }
  const CpuUse cpu = cpuUse(run.usage, 0, run.duration_s);
  double rss_max = 0;
  for (const auto& u : run.usage) rss_max = std::max(rss_max, static_cast<double>(u.server_rss));
  const double rss_first =
      run.usage.empty() ? 0 : static_cast<double>(run.usage.front().server_rss);
  const double rss_last = run.usage.empty() ? 0 : static_cast<double>(run.usage.back().server_rss);
  out +=
      "\n| server CPU % (of one core) | load tool CPU % | machine busy % | server RSS MiB "
      "start / end / max | known cells at end | map versions |\n|---|---|---|---|---|---|\n";
  out +=
      format("| %.0f | %.0f | %.0f | %.0f / %.0f / %.0f | %llu | %llu |\n", cpu.server_pct,
             cpu.load_pct, cpu.machine_busy_pct, rss_first / 1048576.0, rss_last / 1048576.0,
             rss_max / 1048576.0, ull(run.after.known_cells),
             ull(run.after.map_version - std::min(run.after.map_version, run.before.map_version)));
  return out;
}

std::string timelineTable(const RunResult& run, const Scenario& scenario) {
  std::string out =
      "| t s | e2e p50 ms | e2e p99 | scans/s | queries/s | query p99 ms | dropped so far | "
      "server CPU % | server RSS MiB |\n|---|---|---|---|---|---|---|---|---|\n";
  for (const auto& b : timeline(run, scenario.sample_period_s)) {
    out += format("| %.0f | %.1f | %.1f | %.1f | %.1f | %.1f | %llu | %.0f | %.0f |\n", b.t_s,
                  b.e2e.p50, b.e2e.p99, b.scans_per_s, b.queries_per_s, b.query.p99, ull(b.dropped),
                  b.cpu.server_pct, b.server_rss_mib);
  }
  return out;
}

std::string soakSummary(const SoakVerdict& v) {
  return format(
      "soak %s: server RSS peak %.0f MiB in the first window after warm-up, %.0f MiB in the last "
      "(%+.1f%%); e2e p99 %.1f ms in the first window, %.1f ms in the last (%+.1f%%)%s%s\n",
      v.passed ? "passed" : "FAILED", v.rss_at_warm_up_mib, v.rss_max_after_mib, 100 * v.rss_growth,
      v.first_window.p99, v.last_window.p99, 100 * v.p99_drift, v.why.empty() ? "" : ": ",
      v.why.c_str());
}

std::string rampTable(const std::vector<RampStepResult>& steps, bool vary_sensors) {
  std::string out = format(
      "| %s | scans/s | e2e p50 ms | e2e p99 | dropped | queries/s | query p99 ms | failed | "
      "server CPU %% | load tool CPU %% | machine busy %% | SLO |\n"
      "|---|---|---|---|---|---|---|---|---|---|---|---|\n",
      vary_sensors ? "sensors" : "clients");
  for (const auto& s : steps) {
    out += format(
        "| %u | %.1f | %.1f | %.1f | %llu | %.1f | %.1f | %llu | %.0f | %.0f | %.0f | %s |\n",
        s.count, s.scans_per_s, s.slo.e2e.p50, s.slo.e2e.p99, ull(s.slo.dropped), s.queries_per_s,
        s.slo.query.p99, ull(s.slo.failed_queries), s.cpu.server_pct, s.cpu.load_pct,
        s.cpu.machine_busy_pct, s.slo.kept ? "kept" : s.slo.broken.c_str());
  }
  return out;
}

std::string kneeSummary(const std::vector<RampStepResult>& steps, bool vary_sensors,
                        const Slo& slo) {
  const char* what = vary_sensors ? "sensors" : "query clients";
  const std::string slo_text = format(
      "e2e p99 <= %.0f ms, at most %llu dropped, %llu failed queries%s", slo.e2e_p99_ms,
      ull(slo.max_dropped), ull(slo.max_failed_queries),
      slo.query_p99_ms > 0 ? format(", query p99 <= %.0f ms", slo.query_p99_ms).c_str() : "");
  const RampStepResult* last_kept = nullptr;
  const RampStepResult* first_broken = nullptr;
  for (const auto& s : steps) {
    if (s.slo.kept && first_broken == nullptr) last_kept = &s;
    if (!s.slo.kept && first_broken == nullptr) first_broken = &s;
  }
  std::string out = "SLO: " + slo_text + "\n";
  if (first_broken == nullptr) {
    return out + format("knee: not reached; the SLO held up to %u %s (the ramp's last step)\n",
                        steps.empty() ? 0U : steps.back().count, what);
  }
  out += last_kept != nullptr
             ? format("knee: %u %s keep the SLO; %u break it (%s)\n", last_kept->count, what,
                      first_broken->count, first_broken->slo.broken.c_str())
             : format("knee: below the first step; %u %s already break the SLO (%s)\n",
                      first_broken->count, what, first_broken->slo.broken.c_str());
  const CpuUse& c = first_broken->cpu;
  std::string saturated;
  if (c.machine_busy_pct >= 90) {
    saturated =
        format("the machine's CPU (%.0f%% busy: server %.0f%%, load tool %.0f%% of one core)",
               c.machine_busy_pct, c.server_pct, c.load_pct);
  } else if (c.machine_busy_pct >= 75) {
    saturated = format(
        "nearly the machine's CPU (%.0f%% busy: server %.0f%%, load tool %.0f%% of one "
        "core; scheduling delays start before 100%%)",
        c.machine_busy_pct, c.server_pct, c.load_pct);
  } else if (c.server_pct >= 90) {
    saturated = format("the server's integration (%.0f%% of a core, machine %.0f%% busy)",
                       c.server_pct, c.machine_busy_pct);
  } else {
    saturated = format(
        "neither CPU (machine %.0f%% busy, server %.0f%%, load tool %.0f%%): "
        "latency from scheduling or DDS",
        c.machine_busy_pct, c.server_pct, c.load_pct);
  }
  return out + "at the knee the saturated resource is " + saturated + "\n";
}

}  // namespace densemap::load
