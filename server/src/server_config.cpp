#include "densemap/server/server_config.hpp"

#include <arpa/inet.h>
#include <unistd.h>

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <filesystem>

#include "densemap/idl/text_format.hpp"
#include "densemap/io/file_bytes.hpp"
#include "densemap/ros2/names.hpp"
#include "densemap/wire/topics.hpp"
#include "ros2_discovery.hpp"

namespace densemap::server {
namespace {

constexpr std::uint64_t kMaxReserveBlocks = 1'000'000;
constexpr std::uint64_t kBlockBytes = 2304;  // one 8^3 block of the grid store, with its entry
constexpr std::uint64_t kMaxQueryCells = 200'000'000;

/// A number as a person would write it: 1e-09, not 0.000000.
std::string numberText(double v) {
  char text[32];
  std::snprintf(text, sizeof(text), "%g", v);
  return text;
}

std::uint64_t physicalMemoryBytes() {
  const long pages = ::sysconf(_SC_PHYS_PAGES), page = ::sysconf(_SC_PAGESIZE);
  return pages > 0 && page > 0
             ? static_cast<std::uint64_t>(pages) * static_cast<std::uint64_t>(page)
             : std::uint64_t{1} << 34;
}

/// The snapshot file must be a file (or not exist yet) in an existing, writable directory: else
/// the server would lose the map at its first save (or abort at start, as a directory did).
Expected<void> snapshotPathProblem(const std::string& path) {
  if (path.empty()) return {};
  const std::filesystem::path file(path);
  std::error_code ec;
  if (std::filesystem::is_directory(file, ec)) return makeError("'" + path + "' is a directory");
  const std::filesystem::path dir = file.parent_path().empty() ? "." : file.parent_path();
  if (!std::filesystem::is_directory(dir, ec)) {
    return makeError("directory " + dir.string() + " does not exist");
  }
  if (::access(dir.c_str(), W_OK | X_OK) != 0) {
    return makeError("directory " + dir.string() +
                     " is not writable by this user: the map could not be saved");
  }
  return {};
}

}  // namespace

Expected<proto::ServerConfig> loadServerConfig(const std::filesystem::path& file) {
  auto text = readFileBytes(file, std::uint64_t{16} << 20);  // a config is kilobytes
  if (!text) return std::unexpected(text.error());
  proto::ServerConfig config;
  TextLocations where;
  if (auto parsed = parseTextFormat(*text, config, &where); !parsed) {
    return fileError(file, parsed.error().message);
  }
  // Errors found after parsing name the field they are about: file, line and reason.
  const auto refused = [&](const Error& e) {
    return fileError(file, locatedError(where, e.message));
  };
  if (auto options = ingestOptions(config); !options) return refused(options.error());
  if (auto security = securityFiles(config); !security) return refused(security.error());
  if (auto ros2 = ros2Options(config); !ros2) return refused(ros2.error());
  if (auto foxglove = foxgloveOptions(config); !foxglove) return refused(foxglove.error());
  return config;
}

namespace {

/// The map block: backend, kind, resolution, eviction window, range, sensor model.
Expected<void> mapOptions(const proto::ServerConfig& config, PipelineOptions& o) {
  auto backend = parseBackend(config.map().backend());
  if (!backend) return makeError("map.backend: " + backend.error().message);
  o.backend = *backend;
  auto kind = kernel::parseMapKind(config.map().kind());
  if (!kind) return makeError("map.kind: " + kind.error().message);
  o.kernel = *kind;
  o.resolution_m = config.map().resolution_m();
  o.keep_radius_m = config.map().keep_radius_m();
  if (config.map().has_bounds()) {
    const proto::Box& b = config.map().bounds();
    o.bounds = std::make_pair(Point3f(static_cast<float>(b.min_x()), static_cast<float>(b.min_y()),
                                      static_cast<float>(b.min_z())),
                              Point3f(static_cast<float>(b.max_x()), static_cast<float>(b.max_y()),
                                      static_cast<float>(b.max_z())));
  }
  o.max_range_m = config.map().max_range_m();
  if (const proto::DecayConfig& d = config.map().decay(); d.enabled()) {
    if (d.clock() != "arrival" && d.clock() != "stamp") {
      return makeError("map.decay.clock must be \"arrival\" or \"stamp\", got \"" +
                       d.clock().substr(0, 64) + "\"");
    }
    o.decay = DecayOptions{
        .after_s = d.after_s(), .period_s = d.period_s(), .use_stamps = d.clock() == "stamp"};
  }
  const auto& s = config.map().sensor();
  o.sensor = {s.prob_hit(), s.prob_miss(), s.clamp_min(), s.clamp_max()};
  if (auto ok = checkMapOptions(o); !ok) return makeError("map." + ok.error().message);
  // A bound on every ray: with an unlimited range one scan of far points builds ~10^8 cells.
  if (!(o.max_range_m > 0)) {
    return makeError("map.max_range_m must be in (0, " + std::to_string(int(kMaxRangeM)) +
                     "] m (no unlimited range in the server), got " + numberText(o.max_range_m));
  }
  return {};
}

/// The pipeline block: threads, memory reserves and budgets, the queue, integration, limits.
Expected<void> pipelineBlock(const proto::ServerConfig& config, PipelineOptions& o) {
  const auto& p = config.pipeline();
  if (p.threads() < 1 || p.threads() > 256) return makeError("pipeline.threads must be in 1..256");
  // Faulted in at start: more than the machine can hold aborted with bad_alloc.
  if (p.reserve_blocks() > kMaxReserveBlocks ||
      p.reserve_blocks() * kBlockBytes > physicalMemoryBytes() / 4) {
    return makeError(
        "pipeline.reserve_blocks must be at most " + std::to_string(kMaxReserveBlocks) +
        " and a quarter of this machine's memory (" +
        std::to_string(physicalMemoryBytes() / 4 / kBlockBytes) + " blocks of " +
        std::to_string(kBlockBytes) + " bytes), got " + std::to_string(p.reserve_blocks()));
  }
  if (p.request_budget_mb() < 16 || p.request_budget_mb() > 65536) {
    return makeError("pipeline.request_budget_mb must be in 16..65536, got " +
                     std::to_string(p.request_budget_mb()));
  }
  if (p.max_query_cells() < 1 || p.max_query_cells() > kMaxQueryCells) {
    return makeError("pipeline.max_query_cells must be in 1.." + std::to_string(kMaxQueryCells) +
                     ", got " + std::to_string(p.max_query_cells()));
  }
  if (p.query_threads() < 1 || p.query_threads() > 64) {
    return makeError("pipeline.query_threads must be in 1..64");
  }
  if (p.queue_depth() < 1 || p.queue_depth() > 1024) {
    return makeError("pipeline.queue_depth must be in 1..1024");
  }
  if (p.heap_keep_mb() > 1024) {
    return makeError("pipeline.heap_keep_mb must be in 0..1024, got " +
                     std::to_string(p.heap_keep_mb()));
  }
  if (p.queue_budget_mb() < 16 || p.queue_budget_mb() > 65536) {
    return makeError("pipeline.queue_budget_mb must be in 16..65536, got " +
                     std::to_string(p.queue_budget_mb()));
  }
  if (p.max_points() < 1) return makeError("pipeline.max_points must be >= 1");
  auto method = parseIntegrationMethod(p.integration());
  if (!method) return makeError("pipeline.integration: " + method.error().message);
  o.method = *method;
  auto rule = parseUpdateRule(p.update_rule());
  if (!rule) return makeError("pipeline.update_rule: " + rule.error().message);
  o.rule = *rule;
  o.warm_up = p.warm_up();
  o.reserve_blocks = p.reserve_blocks();
  o.limits.max_points = p.max_points();
  o.limits.max_abs_position_m = std::min(p.max_abs_position_m(), 32767.0 * o.resolution_m);
  if (!(p.max_abs_position_m() > 0)) return makeError("pipeline.max_abs_position_m must be > 0");
  return {};
}

/// The upsample block (ILN or interpolation before integration), when enabled.
Expected<void> upsampleOptions(const proto::ServerConfig& config, PipelineOptions& o) {
  if (const auto& u = config.upsample(); u.enabled()) {
    const auto dim = [](std::uint32_t v) { return static_cast<int>(std::min(v, 1U << 20)); };
    auto up = upsample::makeUpsampleOptions(
        u.method(), {dim(u.input_rows()), dim(u.input_cols()), u.top_deg(), u.bottom_deg()},
        {dim(u.output_rows()), dim(u.output_cols()), u.top_deg(), u.bottom_deg()}, u.model());
    if (!up) return makeError("upsample: " + up.error().message);
    o.upsample = std::move(*up);
  }
  return {};
}

/// The snapshot and DDS blocks' checks (their values are the service's: serviceOptions).
Expected<void> checkSnapshotAndDds(const proto::ServerConfig& config) {
  if (config.snapshot().keep() < 1 || config.snapshot().keep() > 100) {
    return makeError("snapshot.keep must be 1 .. 100");
  }
  if (const double period = config.snapshot().autosave_period_s();
      !(period == 0 || (period >= 0.05 && period <= 1e7))) {
    return makeError(
        "snapshot.autosave_period_s must be 0 (off) or 0.05 .. 10000000 s (each autosave "
        "rewrites the whole map), got " +
        numberText(period));
  }
  if (auto dir = snapshotPathProblem(config.snapshot().path()); !dir) {
    return makeError("snapshot.path: " + dir.error().message);
  }
  if (config.dds().domain_id() > 232) return makeError("dds.domain_id must be in 0..232");
  if (const std::string& peer = config.dds().catch_up_from(); !peer.empty()) {
    if (!dds::isInstanceName(peer) || config.dds().instance().empty() ||
        peer == config.dds().instance()) {
      return makeError("dds.catch_up_from: '" + peer +
                       "' must name another instance (1 to 64 letters, digits and _), and "
                       "dds.instance this server's");
    }
    if (config.map().kind() != "log_odds" || config.map().decay().enabled()) {
      return makeError(
          "dds.catch_up_from needs map.kind log_odds without map.decay (a dense "
          "map's evidence and the decay clock are not sent)");
    }
  }
  if (!config.dds().instance().empty() && !dds::isInstanceName(config.dds().instance())) {
    return makeError("dds.instance: '" + config.dds().instance() +
                     "' is not an instance name (1 to 64 letters, digits and _)");
  }
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
  return {};
}

}  // namespace

Expected<PipelineOptions> pipelineOptions(const proto::ServerConfig& config) {
  PipelineOptions o;
  for (auto* part : {&mapOptions, &pipelineBlock, &upsampleOptions}) {
    if (auto ok = part(config, o); !ok) return std::unexpected(ok.error());
  }
  if (auto ok = checkSnapshotAndDds(config); !ok) return std::unexpected(ok.error());
  return o;
}

Expected<IngestOptions> ingestOptions(const proto::ServerConfig& config) {
  auto engine = pipelineOptions(config);
  if (!engine) return std::unexpected(engine.error());
  const auto& p = config.pipeline();
  IngestOptions o{.engine = std::move(*engine),
                  .threads = static_cast<int>(p.threads()),
                  .queue_depth = p.queue_depth(),
                  .queue_budget_bytes = std::size_t{p.queue_budget_mb()} << 20,
                  .distance_field = std::nullopt};
  if (config.esdf().enabled()) {
    const DistanceFieldOptions field{.max_distance_m = config.esdf().max_distance_m()};
    if (auto ok = DistanceField::create(o.engine.resolution_m, field); !ok) {
      return makeError("esdf.max_distance_m: " + ok.error().message);
    }
    o.distance_field = field;
  }
  if (const proto::HistoryConfig& h = config.history(); h.enabled()) {
    if (h.directory().empty()) return makeError("history.directory must name a directory");
    if (h.max_mb() < 1 || h.max_mb() > (std::uint64_t{1} << 24)) {
      return makeError("history.max_mb must be in 1..16777216");
    }
    if (h.checkpoint_every() < 1 || h.checkpoint_every() > 1'000'000) {
      return makeError("history.checkpoint_every must be in 1..1000000");
    }
    if (h.max_checkpoints() < 1 || h.max_checkpoints() > 1024) {
      return makeError("history.max_checkpoints must be in 1..1024");
    }
    if (h.threads() < 1 || h.threads() > 256) return makeError("history.threads must be in 1..256");
    if (o.engine.kernel || o.engine.decay) {
      return makeError("history: pose corrections need map.kind log_odds without map.decay");
    }
    o.history = HistoryOptions{.store = {.directory = h.directory(), .max_bytes = h.max_mb() << 20},
                               .checkpoint_every = h.checkpoint_every(),
                               .max_checkpoints = h.max_checkpoints()};
    o.history_threads = static_cast<int>(h.threads());
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
  if (static_cast<std::size_t>(r.robots_size()) > kMaxRosRobots) {
    return makeError("ros2.robots: at most " + std::to_string(kMaxRosRobots) + " robots");
  }
  for (const std::string& ns : r.robots()) {
    if (ns.empty() || ns == "/" || ros2::inNamespace(ns, "tf").empty()) {
      return makeError("ros2.robots: '" + ns + "' is not a ROS namespace (e.g. \"/robot1\")");
    }
    const std::string canonical = ros2::inNamespace(ns, "tf");
    for (const std::string& other : o.robots) {
      if (ros2::inNamespace(other, "tf") == canonical) {
        return makeError("ros2.robots: '" + ns + "' is listed twice");
      }
    }
    o.robots.push_back(canonical.substr(0, canonical.size() - 3));
  }
  o.robot_pattern = r.robot_pattern();
  if (!o.robot_pattern.empty()) {
    std::string probe = o.robot_pattern;
    std::replace(probe.begin(), probe.end(), '*', 'a');
    std::replace(probe.begin(), probe.end(), '?', 'a');
    if (o.robot_pattern.front() != '/' || ros2::inNamespace(probe, "tf").empty()) {
      return makeError("ros2.robot_pattern: '" + o.robot_pattern +
                       "' is not a namespace glob (e.g. \"/robot*\")");
    }
  }
  if (std::max<std::size_t>(o.robots.size(), 1) * o.clouds.size() > kMaxRosRobots) {
    return makeError("ros2: at most " + std::to_string(kMaxRosRobots) +
                     " cloud topics in all (robots times clouds)");
  }
  for (const std::string* topic :
       {&r.octomap_topic(), &r.grid_topic(), &r.centers_topic(), &r.esdf_slice_topic(),
        &r.costmap_topic(), &r.corrected_path_topic()}) {
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
  o.esdf_slice_topic = r.esdf_slice_topic();
  o.costmap_topic = r.costmap_topic();
  o.corrected_path_topic = r.corrected_path_topic();
  if (!o.corrected_path_topic.empty() && !config.history().enabled()) {
    return makeError("ros2.corrected_path_topic needs the map's history (history.enabled)");
  }
  o.base_frame = r.base_frame();
  while (!o.base_frame.empty() && o.base_frame.front() == '/') o.base_frame.erase(0, 1);
  if (o.base_frame.empty()) return makeError("ros2.base_frame must name a frame");
  if (!std::isfinite(r.esdf_slice_z_m()) || std::abs(r.esdf_slice_z_m()) > 1e6) {
    return makeError("ros2.esdf_slice_z_m must be a finite height, metres");
  }
  o.esdf_slice_z_m = r.esdf_slice_z_m();
  if (!(r.robot_radius_m() >= 0 && r.robot_radius_m() <= 100)) {
    return makeError("ros2.robot_radius_m: 0 .. 100 m");
  }
  o.robot_radius_m = r.robot_radius_m();
  if (!(r.grid_min_z_m() <= r.grid_max_z_m())) {
    return makeError("ros2.grid_min_z_m must be <= grid_max_z_m");
  }
  o.grid_min_z_m = r.grid_min_z_m();
  o.grid_max_z_m = r.grid_max_z_m();
  o.max_points = config.pipeline().max_points();
  if (!ros2::isNodeName(r.node_name())) {
    return makeError("ros2.node_name: '" + r.node_name() +
                     "' is not a ROS node name (letters, digits and '_', not starting with a "
                     "digit, at most 255)");
  }
  o.node_name = r.node_name();
  auto layout = parseRosDistro(r.distro());
  if (!layout) return std::unexpected(layout.error());
  o.gid_layout = *layout;
  return std::optional<Ros2Options>(std::move(o));
}

Expected<bool> isLoopbackAddress(const std::string& address) {
  in_addr v4{};
  in6_addr v6{};
  if (::inet_pton(AF_INET, address.c_str(), &v4) == 1) {
    return (ntohl(v4.s_addr) >> 24) == 127;  // 127.0.0.0/8
  }
  if (::inet_pton(AF_INET6, address.c_str(), &v6) == 1) {
    return IN6_IS_ADDR_LOOPBACK(&v6) != 0;
  }
  return makeError("'" + address.substr(0, 64) + "' is not an IPv4 or IPv6 address");
}

Expected<std::optional<FoxgloveOptions>> foxgloveOptions(const proto::ServerConfig& config) {
  const proto::FoxgloveConfig& f = config.foxglove();
  if (!f.enabled()) return std::optional<FoxgloveOptions>();
  FoxgloveOptions o;
  o.address = f.address();
  const auto loopback = isLoopbackAddress(o.address);
  if (!loopback) return makeError("foxglove.address: " + loopback.error().message);
  if (f.port() == 0 || f.port() > 65535) return makeError("foxglove.port: 1 .. 65535");
  o.port = static_cast<std::uint16_t>(f.port());
  if (f.max_clients() < 1 || f.max_clients() > 1024) {
    return makeError("foxglove.max_clients: 1 .. 1024");
  }
  o.max_clients = f.max_clients();
  if (f.max_queue_bytes() < (std::uint64_t{64} << 10) ||
      f.max_queue_bytes() > (std::uint64_t{1} << 30)) {
    return makeError("foxglove.max_queue_bytes: 65536 .. 1073741824 (64 KiB .. 1 GiB)");
  }
  o.max_queue_bytes = f.max_queue_bytes();
  if (!(f.stall_close_s() >= 0.1 && f.stall_close_s() <= 3600)) {
    return makeError("foxglove.stall_close_s: 0.1 .. 3600 s");
  }
  o.stall_close_s = f.stall_close_s();
  if (!(f.grid_period_s() >= 0.05 && f.grid_period_s() <= 3600)) {
    return makeError("foxglove.grid_period_s: 0.05 .. 3600 s");
  }
  o.grid_period_s = f.grid_period_s();
  if (!std::isfinite(f.grid_min_z_m()) || !std::isfinite(f.grid_max_z_m()) ||
      f.grid_min_z_m() > f.grid_max_z_m()) {
    return makeError("foxglove.grid_min_z_m must be finite and <= grid_max_z_m");
  }
  o.grid_min_z_m = f.grid_min_z_m();
  o.grid_max_z_m = f.grid_max_z_m();
  if (f.voxel_window_cells() < 8 || f.voxel_window_cells() > 256) {
    return makeError("foxglove.voxel_window_cells: 8 .. 256");
  }
  o.voxel_window_cells = f.voxel_window_cells();
  if (f.max_trajectory_poses() < 2 || f.max_trajectory_poses() > 1'000'000) {
    return makeError("foxglove.max_trajectory_poses: 2 .. 1000000");
  }
  o.max_trajectory_poses = f.max_trajectory_poses();
  const auto kind = kernel::parseMapKind(config.map().kind());
  o.voxels = kind && kind->has_value();  // a dense kind
  if (f.has_certificate_chain() != f.has_private_key()) {
    return makeError("foxglove: TLS needs both certificate_chain and private_key");
  }
  if (f.has_certificate_chain()) {
    for (const std::string& file : {f.certificate_chain(), f.private_key()}) {
      if (::access(file.c_str(), R_OK) != 0) {
        return makeError("foxglove: cannot read " + file.substr(0, 256));
      }
    }
    o.tls = FoxgloveOptions::Tls{f.certificate_chain(), f.private_key()};
  }
  if (!*loopback && !o.tls && !f.allow_insecure_remote()) {
    return makeError("foxglove.address '" + o.address +
                     "' is not loopback and there is no TLS: anyone who reaches it could watch "
                     "the map. Set foxglove.certificate_chain and foxglove.private_key (clients "
                     "then open wss://), or set foxglove.allow_insecure_remote: true to accept "
                     "that");
  }
  return std::optional<FoxgloveOptions>(std::move(o));
}

}  // namespace densemap::server
