#include "densemap/server/server_config.hpp"

#include <cmath>

#include "densemap/idl/text_format.hpp"
#include "densemap/io/file_bytes.hpp"
#include "densemap/ros2/names.hpp"

namespace densemap::server {

Expected<proto::ServerConfig> loadServerConfig(const std::filesystem::path& file) {
  auto text = readFileBytes(file);
  if (!text) return std::unexpected(text.error());
  proto::ServerConfig config;
  if (auto parsed = parseTextFormat(*text, config); !parsed) {
    return fileError(file, parsed.error().message);
  }
  if (auto options = pipelineOptions(config); !options) {
    return fileError(file, options.error().message);
  }
  if (auto security = securityFiles(config); !security) {
    return fileError(file, security.error().message);
  }
  return config;
}

Expected<PipelineOptions> pipelineOptions(const proto::ServerConfig& config) {
  PipelineOptions o;
  auto backend = parseBackend(config.map().backend());
  if (!backend) return makeError("map.backend: " + backend.error().message);
  o.backend = *backend;
  if (config.map().kind() != "log_odds") {
    auto kernel = kernel::parseKernelMethod(config.map().kind());
    if (!kernel) {
      return makeError("map.kind: unknown kind '" + config.map().kind() +
                       "' (expected log_odds, akimap, bgk, bgkl or akimap_rays)");
    }
    o.kernel = *kernel;
  }
  o.resolution_m = config.map().resolution_m();
  const double keep = config.map().keep_radius_m();
  if (!std::isfinite(keep) || keep < 0) return makeError("map.keep_radius_m must be >= 0");
  o.keep_radius_m = keep;
  if (config.map().has_bounds()) {
    const proto::Box& b = config.map().bounds();
    const Point3f lo(static_cast<float>(b.min_x()), static_cast<float>(b.min_y()),
                     static_cast<float>(b.min_z()));
    const Point3f hi(static_cast<float>(b.max_x()), static_cast<float>(b.max_y()),
                     static_cast<float>(b.max_z()));
    if (!lo.allFinite() || !hi.allFinite() || (lo.array() >= hi.array()).any()) {
      return makeError("map.bounds needs finite min_x < max_x, min_y < max_y, min_z < max_z");
    }
    o.bounds = std::make_pair(lo, hi);
  }
  if ((o.keep_radius_m > 0 || o.bounds) &&
      (config.map().backend() != "grid" || config.map().kind() != "log_odds")) {
    return makeError(
        "map.keep_radius_m and map.bounds (eviction) need backend \"grid\" and kind "
        "\"log_odds\"");
  }
  if (!(o.resolution_m >= 0.001 && o.resolution_m <= 100.0)) {
    return makeError("map.resolution_m must be in [0.001, 100], got " +
                     std::to_string(o.resolution_m));
  }
  o.max_range_m = config.map().max_range_m();
  if (!std::isfinite(o.max_range_m)) return makeError("map.max_range_m must be finite");
  const auto& s = config.map().sensor();
  o.sensor = {s.prob_hit(), s.prob_miss(), s.clamp_min(), s.clamp_max()};
  if (!SensorModel(o.sensor).isValid() || s.prob_hit() >= 1.0 || s.clamp_max() >= 1.0 ||
      s.prob_miss() <= 0.0 || s.clamp_min() <= 0.0) {
    return makeError(
        "map.sensor needs 0 < clamp_min < 0.5, prob_miss < 0.5 < prob_hit < 1, "
        "0.5 < clamp_max < 1");
  }
  const auto& p = config.pipeline();
  if (p.threads() < 1 || p.threads() > 256) return makeError("pipeline.threads must be in 1..256");
  if (p.reserve_blocks() > 10'000'000) {
    return makeError("pipeline.reserve_blocks must be at most 10000000");
  }
  if (p.query_threads() < 1 || p.query_threads() > 64) {
    return makeError("pipeline.query_threads must be in 1..64");
  }
  if (p.queue_depth() < 1 || p.queue_depth() > 1024) {
    return makeError("pipeline.queue_depth must be in 1..1024");
  }
  if (p.max_points() < 1) return makeError("pipeline.max_points must be >= 1");
  auto method = parseIntegrationMethod(p.integration());
  if (!method) return makeError("pipeline.integration: " + method.error().message);
  o.method = *method;
  auto rule = parseUpdateRule(p.update_rule());
  if (!rule) return makeError("pipeline.update_rule: " + rule.error().message);
  o.rule = *rule;
  o.threads = static_cast<int>(p.threads());
  o.queue_depth = p.queue_depth();
  o.warm_up = p.warm_up();
  o.reserve_blocks = p.reserve_blocks();
  o.limits.max_points = p.max_points();
  o.limits.max_abs_position_m = std::min(p.max_abs_position_m(), 32767.0 * o.resolution_m);
  if (!(p.max_abs_position_m() > 0)) return makeError("pipeline.max_abs_position_m must be > 0");
  if (const auto& u = config.upsample(); u.enabled()) {
    const auto dim = [](std::uint32_t v) { return static_cast<int>(std::min(v, 1U << 20)); };
    auto up = upsample::makeUpsampleOptions(
        u.method(), {dim(u.input_rows()), dim(u.input_cols()), u.top_deg(), u.bottom_deg()},
        {dim(u.output_rows()), dim(u.output_cols()), u.top_deg(), u.bottom_deg()}, u.model());
    if (!up) return makeError("upsample: " + up.error().message);
    o.upsample = std::move(*up);
  }
  if (config.snapshot().keep() < 1 || config.snapshot().keep() > 100) {
    return makeError("snapshot.keep must be 1 .. 100");
  }
  if (config.snapshot().autosave_period_s() < 0) {
    return makeError("snapshot.autosave_period_s must be >= 0");
  }
  if (config.dds().domain_id() > 232) return makeError("dds.domain_id must be in 0..232");
  if (config.dds().network_interface().empty()) {
    return makeError("dds.network_interface must name an interface (default lo)");
  }
  if (!dds::isLoopbackInterface(config.dds().network_interface()) && !config.has_security() &&
      !config.dds().allow_insecure_remote()) {
    return makeError("dds.network_interface '" + config.dds().network_interface() +
                     "' is not loopback and there is no security block: anyone on that "
                     "network could send scans and commands and read the map. Add a security "
                     "block (scripts/make-pki.sh makes its files), or set "
                     "dds.allow_insecure_remote: true to accept that");
  }
  return o;
}

Expected<std::optional<dds::SecurityFiles>> securityFiles(const proto::ServerConfig& config) {
  if (!config.has_security()) return std::optional<dds::SecurityFiles>();
  const proto::SecurityConfig& s = config.security();
  dds::SecurityFiles files{s.identity_ca(),    s.identity_certificate(), s.private_key(),
                           s.permissions_ca(), s.governance(),           s.permissions()};
  if (auto ok = dds::checkSecurityFiles(files); !ok) return std::unexpected(ok.error());
  return std::optional<dds::SecurityFiles>(std::move(files));
}

Expected<std::optional<Ros2Options>> ros2Options(const proto::ServerConfig& config) {
  const proto::Ros2Config& r = config.ros2();
  if (!r.enabled()) return std::optional<Ros2Options>();
  Ros2Options o;
  if (r.clouds_size() > 0) o.clouds.assign(r.clouds().begin(), r.clouds().end());
  for (const std::string& topic : o.clouds) {
    if (ros2::ddsTopicName(topic).empty()) {
      return makeError("ros2.clouds: '" + topic + "' is not a ROS topic name");
    }
  }
  for (const std::string* topic : {&r.octomap_topic(), &r.grid_topic(), &r.centers_topic()}) {
    if (!topic->empty() && ros2::ddsTopicName(*topic).empty()) {
      return makeError("ros2: '" + *topic + "' is not a ROS topic name");
    }
  }
  o.reliable_clouds = r.reliable_clouds();
  o.world_frame = r.world_frame();
  while (!o.world_frame.empty() && o.world_frame.front() == '/') o.world_frame.erase(0, 1);
  if (o.world_frame.empty()) return makeError("ros2.world_frame must name a frame");
  if (!(r.tf_wait_s() >= 0 && r.tf_wait_s() <= 60)) return makeError("ros2.tf_wait_s: 0 .. 60");
  o.tf_wait = std::chrono::milliseconds(static_cast<std::int64_t>(r.tf_wait_s() * 1000));
  if (r.max_waiting_clouds() < 1 || r.max_waiting_clouds() > 100) {
    return makeError("ros2.max_waiting_clouds: 1 .. 100");
  }
  o.max_waiting = r.max_waiting_clouds();
  if (!(r.tf_buffer_s() >= 1 && r.tf_buffer_s() <= 3600)) {
    return makeError("ros2.tf_buffer_s: 1 .. 3600");
  }
  o.tf_buffer_ns = static_cast<std::int64_t>(r.tf_buffer_s() * 1e9);
  if (!(r.publish_period_s() >= 0 && r.publish_period_s() <= 3600)) {
    return makeError("ros2.publish_period_s: 0 .. 3600");
  }
  o.publish_period_s = r.publish_period_s();
  o.octomap_topic = r.octomap_topic();
  o.grid_topic = r.grid_topic();
  o.centers_topic = r.centers_topic();
  if (!(r.grid_min_z_m() <= r.grid_max_z_m())) {
    return makeError("ros2.grid_min_z_m must be <= grid_max_z_m");
  }
  o.grid_min_z_m = r.grid_min_z_m();
  o.grid_max_z_m = r.grid_max_z_m();
  o.max_points = config.pipeline().max_points();
  return std::optional<Ros2Options>(std::move(o));
}

}  // namespace densemap::server
