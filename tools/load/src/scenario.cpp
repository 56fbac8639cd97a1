#include "densemap/load/scenario.hpp"

#include <cctype>
#include <cmath>
#include <cstdio>
#include <numbers>
#include <set>

#include "densemap/idl/text_format.hpp"
#include "densemap/io/file_bytes.hpp"
#include "densemap_load.pb.h"

namespace densemap::load {
namespace {

bool within(double v, double lo, double hi) { return std::isfinite(v) && v >= lo && v <= hi; }

Expected<Transform> poseOffset(const proto::PoseOffset& p, const std::string& field) {
  if (!within(p.x(), -1e4, 1e4) || !within(p.y(), -1e4, 1e4) || !within(p.z(), -1e4, 1e4) ||
      !within(p.yaw_deg(), -360, 360)) {
    return makeError(field + ": x, y, z must be within +-10000 m and yaw_deg within +-360");
  }
  Transform t = Transform::Identity();
  t.translate(Eigen::Vector3d(p.x(), p.y(), p.z()));
  t.rotate(Eigen::AngleAxisd(p.yaw_deg() * std::numbers::pi / 180.0, Eigen::Vector3d::UnitZ()));
  return t;
}

Expected<SensorTemplate> sensorTemplate(const proto::SensorStream& s, std::size_t index) {
  const std::string field = "sensors[" + std::to_string(index) + "]";
  SensorTemplate t;
  SensorPlan& p = t.plan;
  p.sensor_id = s.sensor_id();
  if (p.sensor_id.empty() || p.sensor_id.size() > 48) {
    return makeError(field + ".sensor_id must be 1 .. 48 characters");
  }
  if (s.has_data()) {
    if (s.data().empty()) return makeError(field + ".data is empty");
    p.data = s.data();
  } else if (s.has_sim()) {
    const auto& sim = s.sim();
    if (sim.scans() < 1 || sim.scans() > 100000) {
      return makeError(field + ".sim.scans must be in 1 .. 100000");
    }
    if (!within(sim.max_range_m(), 0, 1000)) {
      return makeError(field + ".sim.max_range_m must be in 0 .. 1000");
    }
    SequenceOptions o;
    o.scene = sim.scene();
    o.sensor = sim.sensor();
    o.scans = static_cast<int>(sim.scans());
    o.max_range_m = sim.max_range_m();
    o.seed = sim.seed();
    o.ground_truth_resolution_m = 0;  // the load tool needs no ground truth
    p.sim = o;
  } else {
    return makeError(field + " needs data or sim");
  }
  if (!within(s.rate_hz(), 0.1, 1000)) return makeError(field + ".rate_hz must be in 0.1 .. 1000");
  if (!within(s.start_offset_s(), 0, kMaxDurationS)) {
    return makeError(field + ".start_offset_s must be in 0 .. 86400");
  }
  if (s.count() < 1 || s.count() > kMaxSensors) {
    return makeError(field + ".count must be in 1 .. " + std::to_string(kMaxSensors));
  }
  auto offset = poseOffset(s.offset(), field + ".offset");
  if (!offset) return std::unexpected(offset.error());
  auto step = poseOffset(s.offset_step(), field + ".offset_step");
  if (!step) return std::unexpected(step.error());
  p.rate_hz = s.rate_hz();
  p.start_offset_s = s.start_offset_s();
  p.offset = *offset;
  p.first = s.first();
  p.limit = s.limit();
  p.loop = s.loop();
  t.offset_step = *step;
  t.count = s.count();
  return t;
}

Expected<ClientTemplate> clientTemplate(const proto::QueryClient& c, std::size_t index,
                                        const std::vector<SensorTemplate>& sensors) {
  const std::string field = "clients[" + std::to_string(index) + "]";
  ClientTemplate t;
  ClientPlan& p = t.plan;
  p.name = c.name();
  if (p.name.empty() || p.name.size() > 48)
    return makeError(field + ".name must be 1 .. 48 characters");
  if (c.count() < 1 || c.count() > kMaxClients) {
    return makeError(field + ".count must be in 1 .. " + std::to_string(kMaxClients));
  }
  if (!within(c.rate_hz(), 0, 10000)) {
    return makeError(field + ".rate_hz must be in 0 .. 10000 (0: closed loop)");
  }
  const double w[kQueryKinds] = {c.point_weight(), c.bbox_weight(), c.ray_weight()};
  double total = 0;
  for (int k = 0; k < kQueryKinds; ++k) {
    if (!within(w[k], 0, 1e6)) return makeError(field + ": weights must be in 0 .. 1e6");
    p.weights[k] = w[k];
    total += w[k];
  }
  if (total <= 0) return makeError(field + ": at least one of the query weights must be > 0");
  if (c.point_batch() < 1 || c.point_batch() > 100000) {
    return makeError(field + ".point_batch must be in 1 .. 100000");
  }
  if (!within(c.bbox_edge_m(), 0.1, 200))
    return makeError(field + ".bbox_edge_m must be in 0.1 .. 200");
  if (!within(c.ray_range_m(), 0.1, 1000))
    return makeError(field + ".ray_range_m must be in 0.1 .. 1000");
  if (!within(c.spread_m(), 0, 1000)) return makeError(field + ".spread_m must be in 0 .. 1000");
  if (c.max_requests() < 1) return makeError(field + ".max_requests must be >= 1");
  p.rate_hz = c.rate_hz();
  p.point_batch = c.point_batch();
  p.bbox_edge_m = c.bbox_edge_m();
  p.ray_range_m = c.ray_range_m();
  p.spread_m = c.spread_m();
  p.max_requests = c.max_requests();
  if (c.has_around_sensor()) {
    p.around_sensor = sensors.size();
    for (std::size_t i = 0; i < sensors.size(); ++i) {
      if (sensors[i].plan.sensor_id == c.around_sensor()) p.around_sensor = i;
    }
    if (p.around_sensor == sensors.size()) {
      return makeError(field + ".around_sensor: no sensor stream '" + c.around_sensor() + "'");
    }
  }
  t.count = c.count();
  return t;
}

std::string sanitized(const std::string& s) {
  std::string out;
  for (const char c : s) out += std::isalnum(static_cast<unsigned char>(c)) != 0 ? c : '_';
  return out;
}

}  // namespace

const char* queryKindName(QueryKind kind) {
  switch (kind) {
    case QueryKind::kPoint:
      return "point";
    case QueryKind::kBox:
      return "bbox";
    case QueryKind::kRay:
      return "ray";
  }
  return "?";
}

std::vector<SensorPlan> expandSensors(const SensorTemplate& t) {
  std::vector<SensorPlan> out;
  Transform offset = t.plan.offset;
  for (std::uint32_t i = 0; i < t.count; ++i) {
    SensorPlan p = t.plan;
    if (t.count > 1) p.sensor_id += "-" + std::to_string(i + 1);
    p.offset = offset;
    p.start_offset_s += static_cast<double>(i) / (p.rate_hz * t.count);
    out.push_back(std::move(p));
    offset = offset * t.offset_step;
  }
  return out;
}

std::vector<ClientPlan> expandClients(const ClientTemplate& t) {
  std::vector<ClientPlan> out;
  for (std::uint32_t i = 0; i < t.count; ++i) {
    ClientPlan p = t.plan;
    if (t.count > 1) p.name += "-" + std::to_string(i + 1);
    out.push_back(std::move(p));
  }
  return out;
}

namespace {

/// The sensor and client blocks: templates, then their copies (ids, offsets, staggered starts).
Expected<void> parseStreams(const proto::Scenario& in, Scenario& s) {
  for (int i = 0; i < in.sensors_size(); ++i) {
    auto t = sensorTemplate(in.sensors(i), static_cast<std::size_t>(i));
    if (!t) return std::unexpected(t.error());
    s.sensor_templates.push_back(std::move(*t));
  }
  for (int i = 0; i < in.clients_size(); ++i) {
    auto t = clientTemplate(in.clients(i), static_cast<std::size_t>(i), s.sensor_templates);
    if (!t) return std::unexpected(t.error());
    s.client_templates.push_back(std::move(*t));
  }
  // Clients query around their sensor's first copy: the template index is the expanded
  // stream's index of that copy.
  std::vector<std::size_t> first_copy;
  for (const auto& t : s.sensor_templates) {
    first_copy.push_back(s.sensors.size());
    for (auto& p : expandSensors(t)) s.sensors.push_back(std::move(p));
  }
  for (auto& t : s.client_templates) {
    if (t.plan.around_sensor < first_copy.size()) {
      t.plan.around_sensor = first_copy[t.plan.around_sensor];
    }
    for (auto& p : expandClients(t)) s.clients.push_back(std::move(p));
  }
  if (s.sensors.size() > kMaxSensors) {
    return makeError("at most " + std::to_string(kMaxSensors) + " sensor streams in all");
  }
  if (s.clients.size() > kMaxClients) {
    return makeError("at most " + std::to_string(kMaxClients) + " query clients in all");
  }
  std::set<std::string> ids;
  for (const auto& p : s.sensors) {
    if (!ids.insert(p.sensor_id).second)
      return makeError("sensor id '" + p.sensor_id + "' repeats");
  }
  return {};
}

/// The late joiners' start times.
Expected<void> parseJoiners(const proto::Scenario& in, Scenario& s) {
  const auto& lj = in.late_joiners();
  if (lj.count() > kMaxJoiners) return makeError("late_joiners.count must be at most 1000");
  if (!within(lj.first_at_s(), 0, kMaxDurationS) || !within(lj.period_s(), 0.1, kMaxDurationS)) {
    return makeError("late_joiners: first_at_s must be >= 0 and period_s >= 0.1");
  }
  for (std::uint32_t i = 0; i < lj.count(); ++i) {
    s.joiner_times_s.push_back(lj.first_at_s() + i * lj.period_s());
  }
  return {};
}

/// The ramp block (after the streams: it copies one of them).
Expected<RampPlan> parseRamp(const proto::Scenario& in, const Scenario& s) {
  const auto& r = in.ramp();
  RampPlan ramp;
  if (r.vary() != "sensors" && r.vary() != "clients") {
    return makeError("ramp.vary must be \"sensors\" or \"clients\"");
  }
  ramp.vary_sensors = r.vary() == "sensors";
  if (ramp.vary_sensors ? s.sensor_templates.empty() : s.client_templates.empty()) {
    return makeError("ramp.vary: the scenario has no " + r.vary() + " to copy");
  }
  if (r.start() < 1 || r.step() < 1 || r.max_steps() < 1 || r.max_steps() > 64) {
    return makeError("ramp: start and step must be >= 1, max_steps in 1 .. 64");
  }
  if (!within(r.step_duration_s(), 1, 3600)) {
    return makeError("ramp.step_duration_s must be in 1 .. 3600");
  }
  ramp.start = r.start();
  ramp.step = r.step();
  ramp.max_steps = r.max_steps();
  ramp.step_duration_s = r.step_duration_s();
  ramp.reset_between_steps = r.reset_between_steps();
  const std::uint64_t most = rampCount(ramp, ramp.max_steps - 1);
  if (most > (ramp.vary_sensors ? kMaxSensors : kMaxClients)) {
    return makeError("ramp: the last step would run " + std::to_string(most) + " " + r.vary() +
                     ", more than allowed");
  }
  return ramp;
}

/// The soak block.
Expected<SoakPlan> parseSoak(const proto::Scenario& in) {
  const auto& k = in.soak();
  if (!within(k.warm_up_s(), 0, kMaxDurationS) || !within(k.max_rss_growth(), 0, 100) ||
      !within(k.max_p99_drift(), 0, 100) || !within(k.window_s(), 1, kMaxDurationS) ||
      !within(k.drift_floor_ms(), 0, 1e6)) {
    return makeError("soak: warm_up_s >= 0, window_s >= 1, growth, drift and floor >= 0");
  }
  return SoakPlan{k.warm_up_s(), k.max_rss_growth(), k.max_p99_drift(), k.window_s(),
                  k.drift_floor_ms()};
}

}  // namespace

Expected<Scenario> parseScenario(const std::string& text) {
  proto::Scenario in;
  if (auto parsed = parseTextFormat(text, in); !parsed) return std::unexpected(parsed.error());
  Scenario s;
  s.name = in.name().empty() ? "unnamed" : in.name();
  if (!within(in.duration_s(), 1, kMaxDurationS))
    return makeError("duration_s must be in 1 .. 86400");
  if (!within(in.sample_period_s(), 0.1, 600))
    return makeError("sample_period_s must be in 0.1 .. 600");
  s.duration_s = in.duration_s();
  s.sample_period_s = in.sample_period_s();
  if (auto ok = parseStreams(in, s); !ok) return std::unexpected(ok.error());
  if (auto ok = parseJoiners(in, s); !ok) return std::unexpected(ok.error());
  if (s.sensors.empty() && s.clients.empty() && s.joiner_times_s.empty()) {
    return makeError("the scenario has no sensors, clients or late joiners");
  }
  const auto& slo = in.slo();
  if (!within(slo.e2e_p99_ms(), 0.001, 1e6) || !within(slo.query_p99_ms(), 0, 1e6)) {
    return makeError("slo: e2e_p99_ms must be > 0 and query_p99_ms >= 0");
  }
  s.slo = {slo.e2e_p99_ms(), slo.max_dropped(), slo.query_p99_ms(), slo.max_failed_queries()};
  if (in.has_ramp()) {
    auto ramp = parseRamp(in, s);
    if (!ramp) return std::unexpected(ramp.error());
    s.ramp = *ramp;
  }
  if (in.has_soak()) {
    auto soak = parseSoak(in);
    if (!soak) return std::unexpected(soak.error());
    s.soak = *soak;
  }
  return s;
}

Expected<Scenario> loadScenario(const std::filesystem::path& file) {
  auto text = readFileBytes(file);
  if (!text) return std::unexpected(text.error());
  auto s = parseScenario(*text);
  if (!s) return fileError(file, s.error().message);
  return s;
}

std::uint32_t rampCount(const RampPlan& ramp, std::uint32_t step) {
  return ramp.start + step * ramp.step;
}

Scenario rampStep(const Scenario& base, std::uint32_t step) {
  Scenario s = base;
  const RampPlan& ramp = *base.ramp;
  s.duration_s = ramp.step_duration_s;
  s.joiner_times_s.clear();
  s.sensors.clear();
  s.clients.clear();
  if (ramp.vary_sensors) {
    SensorTemplate t = base.sensor_templates.front();
    t.count = rampCount(ramp, step);
    s.sensors = expandSensors(t);
    for (std::size_t i = 1; i < base.sensor_templates.size(); ++i) {
      for (auto& p : expandSensors(base.sensor_templates[i])) s.sensors.push_back(std::move(p));
    }
  } else {
    s.sensors = base.sensors;
  }
  for (std::size_t i = 0; i < base.client_templates.size(); ++i) {
    ClientTemplate t = base.client_templates[i];
    if (!ramp.vary_sensors && i == 0) t.count = rampCount(ramp, step);
    // Queries stay around the first stream (whose index does not change with the ramp).
    if (ramp.vary_sensors) t.plan.around_sensor = 0;
    for (auto& p : expandClients(t)) s.clients.push_back(std::move(p));
  }
  return s;
}

std::filesystem::path simDatasetDir(const SequenceOptions& sim,
                                    const std::filesystem::path& work_dir) {
  char range[32];
  std::snprintf(range, sizeof range, "%g", sim.max_range_m);
  return work_dir /
         ("sim-" + sanitized(sim.scene) + "-" + sanitized(sim.sensor) + "-" +
          std::to_string(sim.scans) + "-" + sanitized(range) + "-" + std::to_string(sim.seed));
}

}  // namespace densemap::load
