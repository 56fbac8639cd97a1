// densemap-server: the occupancy-mapping daemon (docs/architecture.md). Scans in over DDS, map
// versions, queries, commands, status, tiles and deltas out; snapshots on command, autosave
// and shutdown.
#include <spdlog/sinks/stdout_color_sinks.h>
#include <spdlog/spdlog.h>
#include <tbb/global_control.h>
#include <CLI/CLI.hpp>

#include <malloc.h>
#include <unistd.h>

#include <cmath>
#include <csignal>
#include <cstdio>
#include <cstdlib>
#include <ctime>
#include <filesystem>

#ifdef DENSEMAP_HAVE_SYSTEMD
#include <systemd/sd-daemon.h>
#endif

#include "catch_up.hpp"
#include "guarded.hpp"
#include "densemap/cli/allocator.hpp"
#include "densemap/cli/guarded_main.hpp"
#include "densemap/server/export_path.hpp"
#include "densemap/server/map_service.hpp"
#include "densemap/server/server_config.hpp"
#include "densemap/store/snapshot.hpp"

namespace {

/// A message to systemd's notify socket (no-op without libsystemd or outside systemd).
void notifySystemd(const char* state) {
#ifdef DENSEMAP_HAVE_SYSTEMD
  sd_notify(0, state);
#else
  (void)state;
#endif
}

int fail(const std::string& message, int code = 1) {
  spdlog::error("{}", message);
  return code;
}

/// Why the server does not start, and its exit status (2: the config or the snapshot is
/// refused, so systemd's RestartPreventExitStatus keeps it from retrying; 1: may pass).
struct Exit {
  std::string message;
  int code = 2;
};
template <class T>
using OrExit = std::expected<T, Exit>;

/// The service's options from the config (DDS, snapshots, requests, security, ROS 2).
OrExit<densemap::server::ServiceOptions> serviceOptions(const densemap::proto::ServerConfig& config,
                                                        int domain_override) {
  densemap::server::ServiceOptions o;
  o.domain_id =
      domain_override >= 0 ? static_cast<std::uint32_t>(domain_override) : config.dds().domain_id();
  o.network_interface = config.dds().network_interface();
  o.instance = config.dds().instance();
  o.snapshot_path = config.snapshot().path();
  o.autosave_period_s = config.snapshot().autosave_period_s();
  o.max_query_cells = config.pipeline().max_query_cells();
  o.request_budget_bytes = std::size_t{config.pipeline().request_budget_mb()} << 20;
  o.query_threads = static_cast<int>(config.pipeline().query_threads());
  o.snapshot_keep = static_cast<int>(config.snapshot().keep());
  o.export_dir = densemap::server::exportDirectory(config.snapshot().export_dir(), o.snapshot_path);
  auto security = densemap::server::securityFiles(config);
  if (!security) return std::unexpected(Exit{"config: " + security.error().message});
  o.security = *security;
  if (*security) {
    spdlog::info("DDS Security on: identity {}, permissions {}", (*security)->identity_certificate,
                 (*security)->permissions);
  } else if (!densemap::dds::isLoopbackInterface(o.network_interface)) {
    spdlog::warn(
        "DDS on {} without security (dds.allow_insecure_remote): anyone on that network can "
        "send scans and commands and read the map",
        o.network_interface);
  }
  auto ros2 = densemap::server::ros2Options(config);
  if (!ros2) return std::unexpected(Exit{"config: " + ros2.error().message});
  o.ros2 = *ros2;
  auto foxglove = densemap::server::foxgloveOptions(config);
  if (!foxglove) return std::unexpected(Exit{"config: " + foxglove.error().message});
  o.foxglove = *foxglove;
  if (o.foxglove && !o.foxglove->tls) {
    bool loopback = densemap::server::isLoopbackAddress(o.foxglove->address).value_or(false);
    if (!loopback) {
      spdlog::warn(
          "Foxglove endpoint on {} without TLS (foxglove.allow_insecure_remote): anyone who "
          "reaches it can watch the map",
          o.foxglove->address);
    }
  }
  return o;
}

/// What a resumed snapshot gives the ingest: the map, its version, its kernel evidence.
struct Resumed {
  std::unique_ptr<densemap::OccupancyMap> map;
  std::uint64_t version = 0;
  std::optional<densemap::kernel::KernelEvidence> kernel_evidence;
};

/// The snapshot's sensor model is the map's: a different one in the config would apply to new
/// scans only, and the next snapshot would record it. Refused, as a
/// different resolution is.
std::optional<Exit> refuseOtherSensor(const densemap::ResumedSnapshot& resumed,
                                      const densemap::PipelineOptions& options) {
  const densemap::SensorProbabilities& was = resumed.snapshot.map->sensorModel().probabilities();
  const densemap::SensorProbabilities& now = options.sensor;
  const auto same = [](double a, double b) { return std::abs(a - b) <= 1e-9; };
  if (same(was.hit, now.hit) && same(was.miss, now.miss) && same(was.clamp_min, now.clamp_min) &&
      same(was.clamp_max, now.clamp_max)) {
    return std::nullopt;
  }
  return Exit{
      fmt::format("snapshot {} was mapped with map.sensor {{ prob_hit: {} prob_miss: {} "
                  "clamp_min: {} clamp_max: {} }} but the config says {{ prob_hit: {} "
                  "prob_miss: {} clamp_min: {} clamp_max: {} }}: set map.sensor to the "
                  "snapshot's values to resume it, or move the snapshot aside to start a "
                  "new map",
                  resumed.file.string(), was.hit, was.miss, was.clamp_min, was.clamp_max, now.hit,
                  now.miss, now.clamp_min, now.clamp_max)};
}

/// A dense map resumes its kernel evidence; a snapshot without it (a log-odds
/// map's, or one saved before) leaves the probabilities standing until new scans reach their
/// cells, which then start again from the prior. Evidence of another kind is dropped.
void keepMatchingEvidence(densemap::ResumedSnapshot& resumed,
                          const densemap::PipelineOptions& options) {
  auto& kernel = resumed.snapshot.kernel;
  const std::string file = resumed.file.string();
  using densemap::kernel::kernelMethodName;
  if (options.kernel && kernel && kernel->method != *options.kernel) {
    spdlog::warn(
        "snapshot {} holds {} evidence, map.kind is {}: its probabilities stand, "
        "its evidence is not resumed",
        file, kernelMethodName(kernel->method), kernelMethodName(*options.kernel));
    kernel.reset();
  } else if (options.kernel && !kernel) {
    spdlog::warn(
        "snapshot {} holds no {} evidence: its probabilities stand until new scans "
        "reach their cells, which then start again from the prior",
        file, kernelMethodName(*options.kernel));
  } else if (!options.kernel && kernel) {
    spdlog::warn(
        "snapshot {} holds {} evidence, map.kind is log_odds: its probabilities go "
        "on as log-odds, the evidence is dropped at the next save",
        file, kernelMethodName(kernel->method));
    kernel.reset();
  }
}

/// The newest readable snapshot, when snapshots are on and one exists.
OrExit<Resumed> resume(const densemap::server::ServiceOptions& service,
                       const densemap::PipelineOptions& options, bool check_only) {
  Resumed r;
  if (service.snapshot_path.empty()) return r;
  auto resumed = densemap::loadNewestSnapshot(service.snapshot_path, service.snapshot_keep,
                                              options.backend, options.resolution_m);
  if (!resumed) {
    return std::unexpected(Exit{"snapshot: " + resumed.error().message, check_only ? 2 : 1});
  }
  if (!*resumed) return r;
  for (const std::string& reason : (*resumed)->skipped) {
    spdlog::warn("skipping an unreadable snapshot: {}", reason);
  }
  if (auto refused = refuseOtherSensor(**resumed, options)) return std::unexpected(*refused);
  auto& loaded = (*resumed)->snapshot;
  spdlog::info("resumed {} (version {}, {} cells)", (*resumed)->file.string(), loaded.version,
               loaded.map->knownCells());
  keepMatchingEvidence(**resumed, options);
  r.map = std::move(loaded.map);
  r.version = loaded.version;
  r.kernel_evidence = std::move(loaded.kernel);
  return r;
}

/// Blocks until SIGINT or SIGTERM and returns which. systemd (Type=notify): ready now; with
/// WatchdogSec, a WATCHDOG=1 every half period while the publish thread goes round (a wedged
/// server stops pinging and systemd restarts it).
int waitForStop(const sigset_t& signals, const densemap::server::MapService& service) {
  notifySystemd("READY=1\nSTATUS=mapping");
  std::uint64_t watchdog_us = 0;
#ifdef DENSEMAP_HAVE_SYSTEMD
  if (sd_watchdog_enabled(0, &watchdog_us) <= 0) watchdog_us = 0;
#endif
  int received = 0;
  while (true) {
    if (watchdog_us == 0) {
      sigwait(&signals, &received);
      return received;
    }
    const std::uint64_t half = watchdog_us / 2;
    const timespec timeout{static_cast<time_t>(half / 1'000'000),
                           static_cast<long>(half % 1'000'000 * 1000)};
    const int sig = sigtimedwait(&signals, nullptr, &timeout);
    if (sig > 0) return sig;
    const auto since = std::chrono::steady_clock::now() - service.heartbeat();
    if (since < std::chrono::seconds(5)) notifySystemd("WATCHDOG=1");
  }
}

/// The shutdown snapshot. The map must not be lost with the process: when
/// the snapshot cannot be written, a rescue copy goes to the first place that takes it, and
/// the log says where. Returns the exit status.
int saveOnShutdown(densemap::server::MapService& service, const densemap::server::Ingest& ingest,
                   const densemap::server::ServiceOptions& options) {
  const std::filesystem::path& snapshot = options.snapshot_path;
  if (snapshot.empty()) return 0;
  auto saved = service.save();
  if (saved) {
    spdlog::info("saved {} ({} bytes, version {})", snapshot.string(), *saved,
                 ingest.view()->version());
    return 0;
  }
  spdlog::error("shutdown snapshot: {}", saved.error().message);
  const std::string name = "densemap-rescue-" + std::to_string(::getpid()) + ".dmap";
  std::error_code ec;  // current_path() throws when the working directory is gone
  for (const std::filesystem::path& dir :
       {options.export_dir, std::filesystem::current_path(ec), std::filesystem::path("/var/tmp")}) {
    if (dir.empty()) continue;
    std::filesystem::create_directories(dir, ec);
    if (auto rescued = service.save(dir / name); rescued) {
      return fail("the map (version " + std::to_string(ingest.view()->version()) +
                  ") was saved to " + (dir / name).string() + " instead: move it to " +
                  snapshot.string() + " to resume it");
    }
  }
  return fail("shutdown snapshot: no rescue copy could be written either: the map is lost");
}

/// The command line.
struct ServerArgs {
  std::string config_path, check_path, log_level = "info";
  int domain_override = -1;
};

void addServerOptions(CLI::App& app, ServerArgs& args) {
  auto* config_option =
      app.add_option("--config", args.config_path, "Server config, protobuf text format")
          ->check(CLI::ExistingFile);
  app.add_option("--check-config", args.check_path,
                 "Check a config (and the snapshot it would resume) and exit: 0 if the server "
                 "would start with it, 2 with the reason if not")
      ->excludes(config_option);
  app.add_option("--domain-id", args.domain_override, "DDS domain id (overrides the config)")
      ->check(CLI::Range(0, 232));
  app.add_option("--log-level", args.log_level,
                 "Least severe message logged: trace, debug (also every refused scan, request "
                 "and ROS cloud), info, warn, error, off")
      ->check(CLI::IsMember({"trace", "debug", "info", "warn", "error", "off"}))
      ->capture_default_str();
}

/// --check-config's answer for a config the server would start with.
void printValid(const std::string& config_path, const densemap::proto::ServerConfig& config,
                const densemap::server::IngestOptions& options,
                const densemap::server::ServiceOptions& service) {
  const std::filesystem::path& snapshot = service.snapshot_path;
  std::printf(
      "densemap-server: %s is valid: %s backend, %s map at %g m, %d threads, DDS domain "
      "%u on %s%s, snapshot %s\n",
      config_path.c_str(), config.map().backend().c_str(), config.map().kind().c_str(),
      options.engine.resolution_m, options.threads, service.domain_id,
      service.network_interface.c_str(), service.security ? " with DDS Security" : "",
      snapshot.empty() ? "off" : snapshot.string().c_str());
}

}  // namespace

static int runMain(int argc, char** argv) {
  // First: it may start the server again, with the heap on huge pages.
  const densemap::cli::HeapPages heap_pages = densemap::cli::heapOnHugePages(argv);
  densemap::cli::serverHeap();
  // SIGINT/SIGTERM are taken by sigwait (waitForStop); block them before any thread starts so
  // that every thread (TBB, Cyclone) inherits the mask.
  sigset_t signals;
  sigemptyset(&signals);
  sigaddset(&signals, SIGINT);
  sigaddset(&signals, SIGTERM);
  pthread_sigmask(SIG_BLOCK, &signals, nullptr);

  ServerArgs args;
  CLI::App app{"densemap-server: real-time occupancy mapping over DDS (loopback by default)"};
  addServerOptions(app, args);
  CLI11_PARSE(app, argc, argv);
  // One line per message on stderr (journald adds the time under systemd).
  spdlog::set_default_logger(spdlog::stderr_color_mt("densemap-server"));
  spdlog::set_pattern("densemap-server: %^%l%$: %v");
  spdlog::set_level(spdlog::level::from_str(args.log_level));
  const char* tunables = std::getenv("GLIBC_TUNABLES");
  spdlog::debug("{} (GLIBC_TUNABLES={})", densemap::cli::describe(heap_pages),
                tunables != nullptr ? tunables : "");
  if (args.config_path.empty() && args.check_path.empty()) {
    return fail("--config FILE is required (or --check-config FILE)", 2);
  }
  const bool check_only = !args.check_path.empty();
  const std::string config_path = check_only ? args.check_path : args.config_path;

  auto config = densemap::server::loadServerConfig(config_path);
  if (!config) return fail("config: " + config.error().message, 2);
  auto options = densemap::server::ingestOptions(*config);
  if (!options) return fail("config: " + options.error().message, 2);
  auto service_options = serviceOptions(*config, args.domain_override);
  if (!service_options) return fail(service_options.error().message, service_options.error().code);
  auto resumed = resume(*service_options, options->engine, check_only);
  if (!resumed) return fail(resumed.error().message, resumed.error().code);
  if (check_only) {
    printValid(config_path, *config, *options, *service_options);
    return 0;
  }
  // A dense map's stage buffers stay in the heap between stages and scans, not faulted in
  // again (a quarter of the page faults at 0.1 m on 64-beam scans: docs/benchmarks.md).
  if (options->engine.kernel) {
    densemap::cli::keepStageBuffersInHeap(std::size_t{config->pipeline().heap_keep_mb()} << 20);
  }
  // TBB's default pool has hardware threads - 1 workers, shared by every arena: on 2 cores a
  // single worker, so a query task could wait for a whole scan's integration. Room for both
  // arenas: the integration arena's workers plus the query arena's.
  tbb::global_control parallelism(
      tbb::global_control::max_allowed_parallelism,
      static_cast<std::size_t>(options->threads + service_options->query_threads));
  auto ingest =
      densemap::server::Ingest::create(*options, std::move(resumed->map), resumed->version);
  if (!ingest) return fail(ingest.error().message);
  if (const auto& evidence = resumed->kernel_evidence) {
    if (auto restored = (*ingest)->restoreKernelEvidence(*evidence); !restored) {
      return fail("snapshot: " + restored.error().message, 2);
    }
    spdlog::info("resumed the {} evidence of {} cells ({} scans)",
                 densemap::kernel::kernelMethodName(evidence->method), evidence->keys.size(),
                 evidence->scans);
    resumed->kernel_evidence.reset();  // its memory
  }
  auto service = densemap::server::MapService::create(**ingest, *service_options);
  // A second server must not start (exit 2: systemd's RestartPreventExitStatus keeps it from
  // retrying); other DDS errors may pass (an interface not up yet at boot): exit 1.
  if (!service &&
      service.error().message.starts_with(densemap::server::MapService::kAnotherServer)) {
    return fail(service.error().message, 2);
  }
  if (!service) return fail("DDS: " + service.error().message);
  const std::string& peer = config->dds().catch_up_from();
  if (!peer.empty()) (*ingest)->beginCatchUp();
  (*ingest)->start();
  (*service)->start();
  // A replica started late takes its peer's map while it runs (scans it takes meanwhile are
  // kept and caught up).
  std::thread catch_up;
  if (!peer.empty()) {
    catch_up = std::thread([&ingest, &service_options, peer] {
      // Whatever the fetch throws (out of memory copying the peer's map) is logged, not fatal.
      densemap::guarded("catch-up", [&] {
        const auto caught = densemap::server::catchUpFrom(**ingest, *service_options, peer, 10.0);
        if (caught) {
          spdlog::info("{}", *caught);
        } else {
          spdlog::error("{}; this replica keeps its own map", caught.error().message);
        }
      });
    });
  }
  spdlog::info("running on DDS domain {}, interface {}{}; {} backend at {} m, {} threads{}",
               service_options->domain_id, service_options->network_interface,
               service_options->security ? " with DDS Security" : "", config->map().backend(),
               options->engine.resolution_m, options->threads,
               service_options->ros2 ? "; ROS 2 face on" : "");

  const int received = waitForStop(signals, **service);
  notifySystemd("STOPPING=1");
  spdlog::info("{}: stopping", received == SIGINT ? "SIGINT" : "SIGTERM");
  if (catch_up.joinable()) catch_up.join();
  (*service)->stop();  // no more scans or requests
  (*ingest)->stop();   // finishes the scan in flight
  if (const int status = saveOnShutdown(**service, **ingest, *service_options); status != 0) {
    return status;
  }
  const auto c = (*ingest)->counters();
  spdlog::info("received {}, integrated {}, dropped {}, rejected {}", c.received, c.integrated,
               c.dropped, c.rejected);
  return 0;
}

int main(int argc, char** argv) {
  return densemap::cli::guardedMain("densemap-server", [&] { return runMain(argc, argv); });
}
