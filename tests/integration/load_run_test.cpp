// densemap load against a real densemap-server process on loopback: several sensors in one map,
// query clients (threads and processes) and a late joiner; every scan sent is accounted for.
#include <gtest/gtest.h>

#include <fstream>

#include "densemap/load/runner.hpp"
#include "densemap/sim/sequence.hpp"
#include "densemap/test_support/data_dir.hpp"
#include "densemap/test_support/server_process.hpp"

namespace densemap::load {
namespace {

using namespace std::chrono_literals;

/// Two robots (30 m apart) at 5 Hz, two clients asking for every query kind, a late joiner.
std::string smallScenarioText(const std::filesystem::path& data) {
  return "name: \"small\" duration_s: 4\n"
         "sensors { sensor_id: \"r\" data: \"" +
         data.string() +
         "\" rate_hz: 5 count: 2 "
         "offset_step { x: 30 } }\n"
         "clients { name: \"v\" count: 2 rate_hz: 20 point_weight: 2 bbox_weight: 1 ray_weight: 1 "
         "point_batch: 200 bbox_edge_m: 5 }\n"
         "late_joiners { count: 1 first_at_s: 2 }\n";
}

Scenario smallScenario(const std::filesystem::path& data) {
  auto s = parseScenario(smallScenarioText(data));
  EXPECT_TRUE(s) << s.error().message;
  return *s;
}

std::filesystem::path simulate(const std::filesystem::path& dir) {
  SequenceOptions o;
  o.scene = "indoor";
  o.sensor = "vlp16";
  o.columns = 600;
  o.scans = 6;
  o.ground_truth_resolution_m = 0;
  EXPECT_TRUE(writeSimulatedSequence(o, dir / "data"));
  return dir / "data";
}

void expectEveryScanAccountedFor(const RunResult& r) {
  ASSERT_EQ(r.sensors.size(), 2U);
  for (const SensorResult& x : r.sensors) {
    // 5 Hz for 4 s, the second copy a tenth of a second later.
    EXPECT_GE(x.sent, 19U) << x.sensor_id;
    EXPECT_LE(x.sent, 20U) << x.sensor_id;
    EXPECT_EQ(x.server.received, x.sent) << x.sensor_id;
    EXPECT_EQ(x.server.integrated + x.server.dropped + x.server.rejected, x.server.received);
    EXPECT_EQ(x.seen, x.server.integrated) << x.sensor_id;  // every integrated scan's event
    EXPECT_EQ(x.server.seq_gaps, 0U);
    EXPECT_EQ(x.e2e.size(), x.seen);
  }
  EXPECT_EQ(r.sensors[0].sensor_id, "r-1");
  EXPECT_EQ(r.sensors[1].sensor_id, "r-2");
  ASSERT_EQ(r.clients.size(), 2U);
  for (const QueryResult& c : r.clients) {
    for (int k = 0; k < kQueryKinds; ++k) {
      EXPECT_GT(c.answered[k], 0U) << c.name << " " << queryKindName(static_cast<QueryKind>(k));
      EXPECT_EQ(c.failed[k], 0U) << c.last_error;
      EXPECT_EQ(c.latency[k].size(), c.answered[k]);
    }
  }
  ASSERT_EQ(r.joiners.size(), 1U);
  EXPECT_TRUE(r.joiners[0].error.empty()) << r.joiners[0].error;
  EXPECT_GT(r.joiners[0].cells, 0U);
  EXPECT_GT(r.joiners[0].version, r.before.map_version);
  EXPECT_GT(r.after.rss_bytes, 0U);
  EXPECT_GT(r.after.cpu_s, 0.0);
  EXPECT_GE(r.usage.size(), 4U);
}

TEST(LoadRun, TwoSensorsTwoClientsAndALateJoinerAreAllCounted) {
  test::TempDir dir;
  test::ServerProcess server(dir.path(), 186, "pipeline { queue_depth: 8 }\n");
  const Scenario s = smallScenario(simulate(dir.path()));
  RunOptions o;
  o.client = {.domain_id = 186, .timeout = 10s};
  o.work_dir = dir.path() / "work";
  o.progress = false;
  const auto start = std::chrono::steady_clock::now();
  auto r = runScenario(s, o);
  ASSERT_TRUE(r) << r.error().message;
  // Bounded: the duration, discovery and at most a few seconds of draining.
  EXPECT_LT(std::chrono::steady_clock::now() - start, 40s);
  expectEveryScanAccountedFor(*r);
  EXPECT_GT(r->after.known_cells, 0U);
  EXPECT_EQ(server.stop(), 0);
}

TEST(LoadRun, QueryClientsAsProcesses) {
  test::TempDir dir;
  test::ServerProcess server(dir.path(), 187, "pipeline { queue_depth: 8 }\n");
  const auto data = simulate(dir.path());
  const Scenario s = smallScenario(data);
  // The children rebuild the scenario from a file, as `densemap load --processes` does.
  const auto file = dir.path() / "small.textproto";
  std::ofstream(file) << smallScenarioText(data);
  RunOptions o;
  o.client = {.domain_id = 187, .timeout = 10s};
  o.work_dir = dir.path() / "work";
  o.progress = false;
  o.processes = true;
  o.self_exe = DENSEMAP_CLI_BIN;
  o.child_args = {"--domain-id", "187",        "--timeout-ms",     "10000", "load", "--scenario",
                  file.string(), "--work-dir", o.work_dir.string()};
  auto r = runScenario(s, o);
  ASSERT_TRUE(r) << r.error().message;
  expectEveryScanAccountedFor(*r);
  for (const QueryResult& c : r->clients) EXPECT_GT(c.cpu_s, 0.0) << c.name;
}

}  // namespace
}  // namespace densemap::load
