// The load tool's scenarios (parsing, checks, copies, ramp steps) and its verdicts (SLO, soak,
// knee), on synthetic results.
#include <gtest/gtest.h>

#include <fstream>

#include "densemap/load/chart.hpp"
#include "densemap/load/report.hpp"
#include "densemap/load/scenario.hpp"
#include "densemap/test_support/data_dir.hpp"

namespace densemap::load {
namespace {

TEST(LoadScenario, EveryExampleParses) {
  for (const auto& entry : std::filesystem::directory_iterator(DENSEMAP_LOAD_SCENARIOS)) {
    auto s = loadScenario(entry.path());
    ASSERT_TRUE(s) << s.error().message;
    EXPECT_FALSE(s->sensors.empty()) << entry.path();
  }
}

TEST(LoadScenario, CopiesGetIdsOffsetsAndStaggeredStarts) {
  auto s = parseScenario(R"(
    name: "t" duration_s: 10
    sensors { sensor_id: "r" data: "/nowhere" rate_hz: 10 count: 3 offset { x: 5 } offset_step { x: 50 yaw_deg: 90 } }
    sensors { sensor_id: "solo" sim { scans: 4 } }
    clients { name: "v" count: 2 around_sensor: "solo" bbox_weight: 1 }
  )");
  ASSERT_TRUE(s) << s.error().message;
  ASSERT_EQ(s->sensors.size(), 4U);
  EXPECT_EQ(s->sensors[0].sensor_id, "r-1");
  EXPECT_EQ(s->sensors[2].sensor_id, "r-3");
  EXPECT_EQ(s->sensors[3].sensor_id, "solo");
  EXPECT_NEAR(s->sensors[0].offset.translation().x(), 5.0, 1e-12);
  EXPECT_NEAR(s->sensors[1].offset.translation().x(), 55.0, 1e-12);
  // The second step is applied in the first copy's rotated frame: +50 m along its y.
  EXPECT_NEAR(s->sensors[2].offset.translation().x(), 55.0, 1e-9);
  EXPECT_NEAR(s->sensors[2].offset.translation().y(), 50.0, 1e-9);
  EXPECT_NEAR(s->sensors[1].start_offset_s, 1.0 / 30.0, 1e-12);
  ASSERT_EQ(s->clients.size(), 2U);
  EXPECT_EQ(s->clients[1].name, "v-2");
  EXPECT_EQ(s->clients[0].around_sensor, 3U);  // the expanded index of "solo"
  EXPECT_DOUBLE_EQ(s->clients[0].weights[1], 1.0);
  ASSERT_TRUE(s->sensors[3].sim);
  EXPECT_EQ(s->sensors[3].sim->scans, 4);
}

TEST(LoadScenario, BadScenariosAreRefusedWithTheFieldOrLine) {
  const std::pair<const char*, const char*> cases[] = {
      {"duration_s: 10\nbogus: 1", "line 2"},
      {"sensors { sensor_id: \"a\" }", "sensors[0] needs data or sim"},
      {"sensors { data: \"x\" rate_hz: 0 }", "rate_hz"},
      {"sensors { data: \"x\" count: 65 }", "count"},
      {"sensors { data: \"x\" } sensors { data: \"y\" }", "repeats"},
      {"sensors { data: \"x\" offset { x: nan } }", "offset"},
      {"clients { point_weight: 0 }", "weights must be > 0"},
      {"clients { point_batch: 0 }", "point_batch"},
      {"sensors { data: \"x\" } clients { around_sensor: \"nope\" }", "around_sensor"},
      {"duration_s: 100000 sensors { data: \"x\" }", "duration_s"},
      {"name: \"empty\"", "no sensors, clients or late joiners"},
      {"sensors { data: \"x\" } ramp { vary: \"clients\" }", "no clients to copy"},
      {"sensors { data: \"x\" } ramp { start: 60 step: 10 max_steps: 3 }", "more than allowed"},
      {"sensors { data: \"x\" } soak { window_s: 0 }", "soak"},
      {"sensors { data: \"x\" } late_joiners { count: 1 period_s: 0 }", "late_joiners"},
  };
  for (const auto& [text, expected] : cases) {
    auto s = parseScenario(text);
    ASSERT_FALSE(s) << text;
    EXPECT_NE(s.error().message.find(expected), std::string::npos)
        << text << " -> " << s.error().message;
  }
}

TEST(LoadScenario, RampStepsCopyTheFirstStreamOrClient) {
  auto s = parseScenario(R"(
    sensors { sensor_id: "r" data: "/x" offset_step { x: 50 } }
    clients { name: "v" }
    late_joiners { count: 3 }
    ramp { vary: "sensors" start: 2 step: 3 max_steps: 4 step_duration_s: 7 }
  )");
  ASSERT_TRUE(s) << s.error().message;
  const Scenario step = rampStep(*s, 2);
  EXPECT_EQ(step.sensors.size(), 8U);  // 2 + 2 * 3
  EXPECT_EQ(step.clients.size(), 1U);
  EXPECT_TRUE(step.joiner_times_s.empty());
  EXPECT_DOUBLE_EQ(step.duration_s, 7.0);
  EXPECT_NEAR(step.sensors[7].offset.translation().x(), 350.0, 1e-9);
  s->ramp->vary_sensors = false;
  const Scenario clients = rampStep(*s, 1);
  EXPECT_EQ(clients.sensors.size(), 1U);
  EXPECT_EQ(clients.clients.size(), 5U);
}

std::vector<Timed> ramp(int n, double ms_from, double ms_to, double t0 = 0, double dt = 0.1) {
  std::vector<Timed> v;
  for (int i = 0; i < n; ++i) {
    v.push_back({t0 + i * dt, ms_from + (ms_to - ms_from) * i / std::max(1, n - 1)});
  }
  return v;
}

TEST(LoadReport, PercentilesAreNearestRank) {
  const auto s = latencyStats(ramp(1000, 1, 1000));  // 1, 2, ..., 1000 ms
  EXPECT_EQ(s.n, 1000U);
  EXPECT_DOUBLE_EQ(s.p50, 500);
  EXPECT_DOUBLE_EQ(s.p99, 990);
  EXPECT_DOUBLE_EQ(s.p999, 999);
  EXPECT_DOUBLE_EQ(s.max, 1000);
  EXPECT_EQ(latencyStats({}).n, 0U);
}

RunResult syntheticRun() {
  RunResult r;
  r.scenario = "synthetic";
  r.duration_s = 100;
  SensorResult s;
  s.sensor_id = "a";
  s.sent = s.seen = 1000;
  s.server.received = s.server.integrated = 1000;
  s.e2e = ramp(1000, 20, 20);
  r.sensors.push_back(s);
  QueryResult q;
  q.name = "v";
  q.latency[0] = ramp(500, 2, 2);
  q.answered[0] = 500;
  r.clients.push_back(q);
  for (int t = 0; t <= 100; ++t) {
    UsageSample u;
    u.t_s = t;
    u.server_cpu_s = 0.5 * t;  // half a core
    u.load_cpu_s = 0.25 * t;
    u.machine_busy_s = 1.0 * t;  // of 2 s per second: 50% busy
    u.machine_total_s = 2.0 * t;
    u.server_rss = 100 << 20;
    r.usage.push_back(u);
  }
  return r;
}

TEST(LoadReport, SloCountsLossAndLatency) {
  RunResult r = syntheticRun();
  Slo slo;
  EXPECT_TRUE(checkSlo(r, slo).kept) << checkSlo(r, slo).broken;
  r.sensors[0].server.dropped = 2;
  r.sensors[0].sent = 1001;  // and one never reached the server
  const auto v = checkSlo(r, slo);
  EXPECT_FALSE(v.kept);
  EXPECT_EQ(v.dropped, 3U);
  EXPECT_NE(v.broken.find("3 scans dropped"), std::string::npos) << v.broken;
  r = syntheticRun();
  r.sensors[0].e2e.back().ms = 500;
  r.sensors[0].e2e[10].ms = 500;  // 2 of 1000 slow: the p99 stays 20 ms
  EXPECT_TRUE(checkSlo(r, slo).kept);
  for (int i = 0; i < 20; ++i) r.sensors[0].e2e[100 + i].ms = 150;
  EXPECT_FALSE(checkSlo(r, slo).kept);
  slo.e2e_p99_ms = 1000;
  slo.query_p99_ms = 1;
  EXPECT_NE(checkSlo(r, slo).broken.find("query p99"), std::string::npos);
}

// The CI soak passed while it dropped 20 scans (a bad first
// window makes a good-looking trend). Drops and the SLO fail the soak too.
TEST(LoadReport, SoakFailsWhenScansAreDroppedOrTheSloBreaksWhateverTheTrend) {
  const SoakPlan plan{.warm_up_s = 20, .window_s = 30};
  RunResult r = syntheticRun();
  for (auto& u : r.usage) u.server_rss = 80 << 20;
  const Slo slo{.e2e_p99_ms = 200};
  ASSERT_TRUE(checkSoak(r, plan, slo).passed) << checkSoak(r, plan, slo).why;
  r.sensors[0].server.dropped = 20;
  EXPECT_TRUE(checkSoak(r, plan).passed);  // the trend alone does not see drops
  auto v = checkSoak(r, plan, slo);
  EXPECT_FALSE(v.passed);
  EXPECT_NE(v.why.find("20 scans dropped"), std::string::npos) << v.why;
  r.sensors[0].server.dropped = 0;
  for (auto& e : r.sensors[0].e2e) {
    if (e.t_s < 50) e.ms = 1279;  // a slow first window: the trend improves, the SLO breaks
  }
  EXPECT_TRUE(checkSoak(r, plan).passed);
  EXPECT_FALSE(checkSoak(r, plan, slo).passed);
}

// 7 of 45 client processes never started and the report said
// "failed 0". A client that did not start breaks the SLO.
TEST(LoadReport, QueryClientsThatNeverStartedBreakTheSlo) {
  RunResult r = syntheticRun();
  const Slo slo{.e2e_p99_ms = 1000};
  ASSERT_TRUE(checkSlo(r, slo).kept) << checkSlo(r, slo).broken;
  r.clients.push_back(QueryResult{.name = "viewer", .started = false});
  const auto v = checkSlo(r, slo);
  EXPECT_FALSE(v.kept);
  EXPECT_NE(v.broken.find("1 query clients failed to start"), std::string::npos) << v.broken;
}

TEST(LoadReport, CpuUseIsPercentOfACoreAndOfTheMachine) {
  const auto c = cpuUse(syntheticRun().usage, 10, 60);
  EXPECT_NEAR(c.server_pct, 50, 1e-9);
  EXPECT_NEAR(c.load_pct, 25, 1e-9);
  EXPECT_NEAR(c.machine_busy_pct, 50, 1e-9);
}

TEST(LoadReport, SoakFailsOnRssGrowthOrP99DriftAfterWarmUp) {
  const SoakPlan plan{.warm_up_s = 20, .window_s = 30};
  RunResult r = syntheticRun();
  for (auto& u : r.usage) {
    if (u.t_s < 20) u.server_rss = 50 << 20;  // growth during warm-up does not count
    if (u.t_s >= 20 && static_cast<int>(u.t_s) % 10 == 5) u.server_rss = 80 << 20;  // a sawtooth
  }
  EXPECT_TRUE(checkSoak(r, plan).passed) << checkSoak(r, plan).why;
  r.usage[90].server_rss = 115 << 20;  // a higher peak in the last window
  auto v = checkSoak(r, plan);
  EXPECT_FALSE(v.passed);
  EXPECT_NEAR(v.rss_growth, 0.15, 1e-9);
  r.usage[90].server_rss = 105 << 20;
  EXPECT_TRUE(checkSoak(r, plan).passed);
  r.usage[90].server_rss = 100 << 20;
  r.usage[30].server_rss = 115 << 20;  // a peak in the middle, not a trend
  EXPECT_TRUE(checkSoak(r, plan).passed);
  // The last 30 s at 30 ms against 20 ms: +50%, 10 ms over the 5 ms floor.
  for (auto& e : r.sensors[0].e2e) {
    if (e.t_s >= 70) e.ms = 30;
  }
  v = checkSoak(r, plan);
  EXPECT_FALSE(v.passed);
  EXPECT_NEAR(v.p99_drift, 0.5, 1e-9);
  EXPECT_NE(v.why.find("drifted"), std::string::npos);
  // Within the floor: 20 -> 24 ms is +20% but 4 ms, scheduling noise on a shared machine.
  for (auto& e : r.sensors[0].e2e) {
    if (e.t_s >= 70) e.ms = 24.5;
  }
  EXPECT_TRUE(checkSoak(r, plan).passed);
}

TEST(LoadReport, KneeIsTheLastStepThatKeptTheSlo) {
  std::vector<RampStepResult> steps(3);
  for (std::uint32_t i = 0; i < 3; ++i) steps[i].count = i + 1;
  steps[2].slo.kept = false;
  steps[2].slo.broken = "e2e p99 150.0 ms > 100 ms";
  steps[2].cpu = {150, 20, 97};
  const std::string knee = kneeSummary(steps, true, Slo{});
  EXPECT_NE(knee.find("knee: 2 sensors keep the SLO; 3 break it"), std::string::npos) << knee;
  EXPECT_NE(knee.find("the machine's CPU"), std::string::npos) << knee;
  steps.pop_back();
  EXPECT_NE(kneeSummary(steps, true, Slo{}).find("not reached"), std::string::npos);
}

TEST(LoadReport, JsonTimelineAndChartAreWritten) {
  test::TempDir dir;
  Scenario s;
  s.sample_period_s = 10;
  s.soak = SoakPlan{.warm_up_s = 20, .window_s = 30};
  const RunResult r = syntheticRun();
  const auto bins = timeline(r, 10);
  ASSERT_EQ(bins.size(), 10U);
  EXPECT_DOUBLE_EQ(bins[3].scans_per_s, 10.0);    // 1000 scans over 100 s
  EXPECT_DOUBLE_EQ(bins[3].queries_per_s, 10.0);  // 500 queries in the first 50 s
  EXPECT_DOUBLE_EQ(bins[7].queries_per_s, 0.0);
  ASSERT_TRUE(writeJson(dir.path() / "load.json", r, s));
  std::ifstream in(dir.path() / "load.json");
  const std::string json((std::istreambuf_iterator<char>(in)), std::istreambuf_iterator<char>());
  for (const char* key : {"\"scenario\":\"synthetic\"", "\"soak\":{\"passed\":true",
                          "\"timeline\":[", "\"sensors\":[{\"sensor_id\":\"a\",\"sent\":1000"}) {
    EXPECT_NE(json.find(key), std::string::npos) << key;
  }
  ASSERT_TRUE(writeRunChart(dir.path() / "load.png", r, s));
  EXPECT_GT(std::filesystem::file_size(dir.path() / "load.png"), 1000U);
}

}  // namespace
}  // namespace densemap::load
