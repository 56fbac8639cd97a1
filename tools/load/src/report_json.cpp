// densemap load's JSON reports: a run's and a ramp's (the tables' figures, machine-readable).
#include <cstdio>
#include <fstream>
#include <sstream>
#include <thread>

#include "densemap/load/report.hpp"

namespace densemap::load {
namespace {

class Json {
 public:
  Json& open(const char* key, char bracket) {
    comma();
    if (key != nullptr) out_ << '"' << key << "\":";
    out_ << bracket;
    first_ = true;
    return *this;
  }
  Json& close(char bracket) {
    out_ << bracket;
    first_ = false;
    return *this;
  }
  Json& num(const char* key, double v) {
    comma();
    if (key != nullptr) out_ << '"' << key << "\":";
    if (std::isfinite(v)) {
      char buf[32];
      std::snprintf(buf, sizeof buf, "%.6g", v);
      out_ << buf;
    } else {
      out_ << "null";
    }
    return *this;
  }
  Json& str(const char* key, const std::string& v) {
    comma();
    if (key != nullptr) out_ << '"' << key << "\":";
    out_ << '"';
    for (const char c : v) {
      if (c == '"' || c == '\\') {
        out_ << '\\' << c;
      } else if (static_cast<unsigned char>(c) < 0x20) {
        char buf[8];
        std::snprintf(buf, sizeof buf, "\\u%04x", static_cast<unsigned>(c));
        out_ << buf;
      } else {
        out_ << c;
      }
    }
    out_ << '"';
    return *this;
  }
  Json& boolean(const char* key, bool v) {
    comma();
    out_ << '"' << key << "\":" << (v ? "true" : "false");
    return *this;
  }
  Json& stats(const char* key, const LatencyStats& s) {
    open(key, '{').num("n", static_cast<double>(s.n)).num("p50_ms", s.p50).num("p99_ms", s.p99);
    return num("p999_ms", s.p999).num("max_ms", s.max).close('}');
  }
  [[nodiscard]] std::string text() const { return out_.str(); }

 private:
  void comma() {
    if (!first_) out_ << ',';
    first_ = false;
  }
  std::ostringstream out_;
  bool first_ = true;
};

Expected<void> writeText(const std::filesystem::path& file, const std::string& text) {
  std::ofstream out(file);
  out << text << '\n';
  if (!out) return makeError("cannot write " + file.string());
  return {};
}

void sloJson(Json& j, const SloVerdict& v) {
  j.open("slo", '{').boolean("kept", v.kept).str("broken", v.broken);
  j.stats("e2e", v.e2e).stats("query", v.query);
  j.num("dropped", static_cast<double>(v.dropped));
  j.num("failed_queries", static_cast<double>(v.failed_queries)).close('}');
}

void cpuJson(Json& j, const char* key, const CpuUse& c) {
  j.open(key, '{').num("server_pct", c.server_pct).num("load_tool_pct", c.load_pct);
  j.num("machine_busy_pct", c.machine_busy_pct).close('}');
}

}  // namespace

Expected<void> writeJson(const std::filesystem::path& file, const RunResult& run,
                         const Scenario& scenario) {
  Json j;
  j.open(nullptr, '{').str("scenario", run.scenario).num("duration_s", run.duration_s);
  sloJson(j, checkSlo(run, scenario.slo));
  if (scenario.soak) {
    const SoakVerdict s = checkSoak(run, *scenario.soak, scenario.slo);
    j.open("soak", '{').boolean("passed", s.passed).str("why", s.why);
    j.num("rss_at_warm_up_mib", s.rss_at_warm_up_mib).num("rss_max_after_mib", s.rss_max_after_mib);
    j.num("rss_growth", s.rss_growth).stats("first_window", s.first_window);
    j.stats("last_window", s.last_window).num("p99_drift", s.p99_drift).close('}');
  }
  cpuJson(j, "cpu", cpuUse(run.usage, 0, run.duration_s));
  j.open("sensors", '[');
  for (const auto& s : run.sensors) {
    j.open(nullptr, '{').str("sensor_id", s.sensor_id).num("sent", static_cast<double>(s.sent));
    j.num("received", static_cast<double>(s.server.received));
    j.num("integrated", static_cast<double>(s.server.integrated));
    j.num("dropped", static_cast<double>(s.server.dropped));
    j.num("rejected", static_cast<double>(s.server.rejected));
    j.num("seq_gaps", static_cast<double>(s.server.seq_gaps));
    j.num("seen", static_cast<double>(s.seen)).num("late_sends", static_cast<double>(s.late_sends));
    j.stats("e2e", latencyStats(s.e2e)).close('}');
  }
  j.close(']').open("clients", '[');
  for (const auto& c : run.clients) {
    j.open(nullptr, '{').str("name", c.name).num("late_ticks", static_cast<double>(c.late_ticks));
    j.str("last_error", c.last_error).open("kinds", '[');
    for (int k = 0; k < kQueryKinds; ++k) {
      j.open(nullptr, '{').str("kind", queryKindName(static_cast<QueryKind>(k)));
      j.num("answered", static_cast<double>(c.answered[k]));
      j.num("failed", static_cast<double>(c.failed[k]));
      j.num("timeouts", static_cast<double>(c.timeouts[k]));
      j.stats("latency", latencyStats(c.latency[k])).close('}');
    }
    j.close(']').close('}');
  }
  j.close(']').open("late_joiners", '[');
  for (const auto& x : run.joiners) {
    j.open(nullptr, '{').num("at_s", x.at_s).num("seconds", x.seconds);
    j.num("cells", static_cast<double>(x.cells)).num("version", static_cast<double>(x.version));
    j.num("versions_behind", static_cast<double>(x.versions_behind)).str("error", x.error);
    j.close('}');
  }
  j.close(']').open("timeline", '[');
  for (const auto& b : timeline(run, scenario.sample_period_s)) {
    j.open(nullptr, '{').num("t_s", b.t_s).stats("e2e", b.e2e).num("scans_per_s", b.scans_per_s);
    j.num("queries_per_s", b.queries_per_s).stats("query", b.query);
    cpuJson(j, "cpu", b.cpu);
    j.num("server_rss_mib", b.server_rss_mib).close('}');
  }
  j.close(']').close('}');
  return writeText(file, j.text());
}

Expected<void> writeRampJson(const std::filesystem::path& file,
                             const std::vector<RampStepResult>& steps, const Scenario& scenario) {
  Json j;
  j.open(nullptr, '{').str("scenario", scenario.name);
  j.str("vary", scenario.ramp && scenario.ramp->vary_sensors ? "sensors" : "clients");
  j.str("knee", kneeSummary(steps, !scenario.ramp || scenario.ramp->vary_sensors, scenario.slo));
  j.open("steps", '[');
  for (const auto& s : steps) {
    j.open(nullptr, '{').num("count", s.count).num("scans_per_s", s.scans_per_s);
    j.num("queries_per_s", s.queries_per_s);
    sloJson(j, s.slo);
    cpuJson(j, "cpu", s.cpu);
    j.close('}');
  }
  j.close(']').close('}');
  return writeText(file, j.text());
}

}  // namespace densemap::load
