// densemap load's PNG charts: a run's timeline and a ramp's steps (chart.hpp draws them).
#include <algorithm>
#include <array>
#include <cmath>
#include <thread>

#include "densemap/load/chart.hpp"
#include "densemap/load/report.hpp"

namespace densemap::load {

namespace {
constexpr std::array<std::uint8_t, 3> kBlue{20, 60, 200}, kRed{210, 30, 30}, kGreen{20, 150, 60},
    kBlack{0, 0, 0}, kOrange{230, 130, 0};
}  // namespace

Expected<void> writeRunChart(const std::filesystem::path& file, const RunResult& run,
                             const Scenario& scenario) {
  const auto bins = timeline(run, scenario.sample_period_s);
  std::vector<double> x;
  Series e50{"e2e p50", kBlue, {}}, e99{"e2e p99", kRed, {}}, q99{"query p99", kGreen, {}};
  Series scans{"scans/s", kBlue, {}}, queries{"queries/s", kGreen, {}};
  Series server{"server", kRed, {}}, tool{"load tool", kGreen, {}},
      busy{"machine busy", kBlack, {}};
  Series rss{"server RSS", kOrange, {}};
  const double nan = std::nan("");
  for (const auto& b : bins) {
    x.push_back(b.t_s + scenario.sample_period_s / 2);
    e50.y.push_back(b.e2e.n > 0 ? b.e2e.p50 : nan);
    e99.y.push_back(b.e2e.n > 0 ? b.e2e.p99 : nan);
    q99.y.push_back(b.query.n > 0 ? b.query.p99 : nan);
    scans.y.push_back(b.scans_per_s);
    queries.y.push_back(b.queries_per_s);
    server.y.push_back(b.cpu.server_pct);
    tool.y.push_back(b.cpu.load_pct);
    busy.y.push_back(b.cpu.machine_busy_pct *
                     static_cast<double>(std::max(1U, std::thread::hardware_concurrency())));
    rss.y.push_back(b.server_rss_mib);
  }
  std::vector<Panel> panels = {{"latency ms", {e50, e99, q99}},
                               {"", {scans}},
                               {"", {queries}},
                               {"cpu % of a core", {server, tool, busy}},
                               {"mib", {rss}}};
  return writeChart(file, run.scenario, "time s", x, panels);
}

Expected<void> writeRampChart(const std::filesystem::path& file,
                              const std::vector<RampStepResult>& steps, const Scenario& scenario) {
  std::vector<double> x;
  Series e50{"e2e p50", kBlue, {}}, e99{"e2e p99", kRed, {}}, q99{"query p99", kGreen, {}};
  Series scans{"scans/s", kBlue, {}}, queries{"queries/s", kGreen, {}};
  Series server{"server", kRed, {}}, tool{"load tool", kGreen, {}},
      busy{"machine busy", kBlack, {}};
  for (const auto& s : steps) {
    x.push_back(s.count);
    e50.y.push_back(s.slo.e2e.p50);
    e99.y.push_back(s.slo.e2e.p99);
    q99.y.push_back(s.slo.query.p99);
    scans.y.push_back(s.scans_per_s);
    queries.y.push_back(s.queries_per_s);
    server.y.push_back(s.cpu.server_pct);
    tool.y.push_back(s.cpu.load_pct);
    busy.y.push_back(s.cpu.machine_busy_pct *
                     static_cast<double>(std::max(1U, std::thread::hardware_concurrency())));
  }
  const bool sensors = !scenario.ramp || scenario.ramp->vary_sensors;
  std::vector<Panel> panels = {{"latency ms", {e50, e99, q99}},
                               {"", {scans}},
                               {"", {queries}},
                               {"cpu % of a core", {server, tool, busy}}};
  return writeChart(file, scenario.name + " ramp", sensors ? "sensors" : "query clients", x,
                    panels);
}

}  // namespace densemap::load
