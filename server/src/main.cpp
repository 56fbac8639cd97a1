// densemap-server: the occupancy-mapping daemon (DESIGN.md). Scans in over DDS, map versions,
// queries, commands, status, tiles and deltas out; snapshots on command, autosave and shutdown.
#include <spdlog/sinks/stdout_color_sinks.h>
#include <spdlog/spdlog.h>
#include <tbb/global_control.h>
#include <CLI/CLI.hpp>

#include <malloc.h>
#include <unistd.h>

#include <cmath>
#include <csignal>
#include <cstdio>
#include <ctime>
#include <filesystem>

#ifdef DENSEMAP_HAVE_SYSTEMD
#include <systemd/sd-daemon.h>
#endif

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

}  // namespace

static int runMain(int argc, char** argv) {
  // Scans, their world-frame copies and DDS buffers are megabytes each, every scan: keep such
  // blocks in the heap for reuse instead of mmap/munmap per buffer (each fresh mapping costs a
  // page fault per 4 KiB; profiles of 64-beam replays showed 5% of the time there).
  mallopt(M_MMAP_THRESHOLD, 64 << 20);
  // Free memory at the top of a heap beyond 32 MiB goes back to the OS. A thread's heap arena
  // gives its top back only past this threshold (malloc_trim does not trim it): at 256 MiB an
  // 8-client point-query flood left 53-105 MiB of a 49 MiB server behind, at 32 MiB 52 MiB;
  // scans at 10 Hz were not slower (64-beam at 0.1 m, log_odds: p50 80-86 against 85-88 ms).
  mallopt(M_TRIM_THRESHOLD, 32 << 20);
  // Two heap arenas for all threads (glibc makes up to 8 per core): fewer thread heaps to hold
  // freed memory after point-query floods (6 clients x 3M points, with the 256 MiB threshold:
  // 46 of 120 MiB stayed, 105 of 129 with the default arenas); integration rates at 10 Hz did
  // not change (issue 28, item 9).
  mallopt(M_ARENA_MAX, 2);
  // SIGINT/SIGTERM are taken by sigwait below; block them before any thread starts so that
  // every thread (TBB, Cyclone) inherits the mask.
  sigset_t signals;
  sigemptyset(&signals);
  sigaddset(&signals, SIGINT);
  sigaddset(&signals, SIGTERM);
  pthread_sigmask(SIG_BLOCK, &signals, nullptr);

  std::string config_path, check_path;
  int domain_override = -1;
  CLI::App app{"densemap-server: real-time occupancy mapping over DDS (loopback by default)"};
  auto* config_option =
      app.add_option("--config", config_path, "Server config, protobuf text format")
          ->check(CLI::ExistingFile);
  app.add_option("--check-config", check_path,
                 "Check a config (and the snapshot it would resume) and exit: 0 if the server "
                 "would start with it, 2 with the reason if not")
      ->excludes(config_option);
  app.add_option("--domain-id", domain_override, "DDS domain id (overrides the config)")
      ->check(CLI::Range(0, 232));
  std::string log_level = "info";
  app.add_option("--log-level", log_level,
                 "Least severe message logged: trace, debug (also every refused scan, request "
                 "and ROS cloud), info, warn, error, off")
      ->check(CLI::IsMember({"trace", "debug", "info", "warn", "error", "off"}))
      ->capture_default_str();
  CLI11_PARSE(app, argc, argv);
  // One line per message on stderr (journald adds the time under systemd).
  spdlog::set_default_logger(spdlog::stderr_color_mt("densemap-server"));
  spdlog::set_pattern("densemap-server: %^%l%$: %v");
  spdlog::set_level(spdlog::level::from_str(log_level));
  if (config_path.empty() && check_path.empty()) {
    return fail("--config FILE is required (or --check-config FILE)", 2);
  }
  const bool check_only = !check_path.empty();
  if (check_only) config_path = check_path;

  auto config = densemap::server::loadServerConfig(config_path);
  if (!config) return fail("config: " + config.error().message, 2);
  auto options = densemap::server::pipelineOptions(*config);
  if (!options) return fail("config: " + options.error().message, 2);

  densemap::server::ServiceOptions service_options;
  service_options.domain_id = domain_override >= 0 ? static_cast<std::uint32_t>(domain_override)
                                                   : config->dds().domain_id();
  service_options.network_interface = config->dds().network_interface();
  service_options.snapshot_path = config->snapshot().path();
  service_options.autosave_period_s = config->snapshot().autosave_period_s();
  service_options.max_query_cells = config->pipeline().max_query_cells();
  service_options.request_budget_bytes = std::size_t{config->pipeline().request_budget_mb()} << 20;
  service_options.query_threads = static_cast<int>(config->pipeline().query_threads());
  auto security = densemap::server::securityFiles(*config);
  if (!security) return fail("config: " + security.error().message, 2);
  service_options.security = *security;
  if (*security) {
    spdlog::info("DDS Security on: identity {}, permissions {}", (*security)->identity_certificate,
                 (*security)->permissions);
  } else if (!densemap::dds::isLoopbackInterface(service_options.network_interface)) {
    spdlog::warn(
        "DDS on {} without security (dds.allow_insecure_remote): anyone on that network can "
        "send scans and commands and read the map",
        service_options.network_interface);
  }
  auto ros2 = densemap::server::ros2Options(*config);
  if (!ros2) return fail("config: " + ros2.error().message, 2);
  service_options.ros2 = *ros2;

  std::unique_ptr<densemap::OccupancyMap> initial;
  std::uint64_t version = 0;
  std::optional<densemap::kernel::KernelEvidence> kernel_evidence;
  const auto& snapshot = service_options.snapshot_path;
  service_options.snapshot_keep = static_cast<int>(config->snapshot().keep());
  service_options.export_dir =
      densemap::server::exportDirectory(config->snapshot().export_dir(), snapshot);
  auto resumed = snapshot.empty()
                     ? densemap::Expected<std::optional<densemap::ResumedSnapshot>>(std::nullopt)
                     : densemap::loadNewestSnapshot(snapshot, service_options.snapshot_keep,
                                                    options->backend, options->resolution_m);
  if (!resumed) return fail("snapshot: " + resumed.error().message, check_only ? 2 : 1);
  if (*resumed) {
    auto* loaded = &(*resumed)->snapshot;
    for (const std::string& reason : (*resumed)->skipped) {
      spdlog::warn("skipping an unreadable snapshot: {}", reason);
    }
    // The snapshot's sensor model is the map's: a different one in the config would apply to
    // new scans only, and the next snapshot would record it (issue 28, item 7). Refused, as a
    // different resolution is.
    const densemap::SensorProbabilities& was = loaded->map->sensorModel().probabilities();
    const densemap::SensorProbabilities& now = options->sensor;
    const auto same = [](double a, double b) { return std::abs(a - b) <= 1e-9; };
    if (!same(was.hit, now.hit) || !same(was.miss, now.miss) ||
        !same(was.clamp_min, now.clamp_min) || !same(was.clamp_max, now.clamp_max)) {
      return fail(
          fmt::format("snapshot {} was mapped with map.sensor {{ prob_hit: {} prob_miss: {} "
                      "clamp_min: {} clamp_max: {} }} but the config says {{ prob_hit: {} "
                      "prob_miss: {} clamp_min: {} clamp_max: {} }}: set map.sensor to the "
                      "snapshot's values to resume it, or move the snapshot aside to start a "
                      "new map",
                      (*resumed)->file.string(), was.hit, was.miss, was.clamp_min, was.clamp_max,
                      now.hit, now.miss, now.clamp_min, now.clamp_max),
          2);
    }
    spdlog::info("resumed {} (version {}, {} cells)", (*resumed)->file.string(), loaded->version,
                 loaded->map->knownCells());
    // A dense map resumes its kernel evidence (issue 29); a snapshot without it (a log-odds
    // map's, or one saved before) leaves the probabilities standing until new scans reach
    // their cells, which then start again from the prior.
    if (options->kernel && loaded->kernel && loaded->kernel->method != *options->kernel) {
      spdlog::warn("snapshot {} holds {} evidence, map.kind is {}: its probabilities stand, "
                   "its evidence is not resumed",
                   (*resumed)->file.string(),
                   densemap::kernel::kernelMethodName(loaded->kernel->method),
                   densemap::kernel::kernelMethodName(*options->kernel));
      loaded->kernel.reset();
    } else if (options->kernel && !loaded->kernel) {
      spdlog::warn("snapshot {} holds no {} evidence: its probabilities stand until new scans "
                   "reach their cells, which then start again from the prior",
                   (*resumed)->file.string(),
                   densemap::kernel::kernelMethodName(*options->kernel));
    } else if (!options->kernel && loaded->kernel) {
      spdlog::warn("snapshot {} holds {} evidence, map.kind is log_odds: its probabilities go "
                   "on as log-odds, the evidence is dropped at the next save",
                   (*resumed)->file.string(),
                   densemap::kernel::kernelMethodName(loaded->kernel->method));
      loaded->kernel.reset();
    }
    initial = std::move(loaded->map);
    version = loaded->version;
    kernel_evidence = std::move(loaded->kernel);
  }
  if (check_only) {
    std::printf(
        "densemap-server: %s is valid: %s backend, %s map at %g m, %d threads, DDS domain "
        "%u on %s%s, snapshot %s\n",
        config_path.c_str(), config->map().backend().c_str(), config->map().kind().c_str(),
        options->resolution_m, options->threads, service_options.domain_id,
        service_options.network_interface.c_str(), *security ? " with DDS Security" : "",
        snapshot.empty() ? "off" : snapshot.string().c_str());
    return 0;
  }
  // TBB's default pool has hardware threads - 1 workers, shared by every arena: on 2 cores a
  // single worker, so a query task could wait for a whole scan's integration. Room for both
  // arenas: the integration arena's workers plus the query arena's.
  tbb::global_control parallelism(
      tbb::global_control::max_allowed_parallelism,
      static_cast<std::size_t>(options->threads + service_options.query_threads));
  auto pipeline = densemap::Ingest::create(*options, std::move(initial), version);
  if (!pipeline) return fail(pipeline.error().message);
  if (kernel_evidence) {
    if (auto restored = (*pipeline)->restoreKernelEvidence(*kernel_evidence); !restored) {
      return fail("snapshot: " + restored.error().message, 2);
    }
    spdlog::info("resumed the {} evidence of {} cells ({} scans)",
                 densemap::kernel::kernelMethodName(kernel_evidence->method),
                 kernel_evidence->keys.size(), kernel_evidence->scans);
    kernel_evidence.reset();  // its memory
  }
  auto service = densemap::server::MapService::create(**pipeline, service_options);
  // A second server must not start (exit 2: systemd's RestartPreventExitStatus keeps it from
  // retrying); other DDS errors may pass (an interface not up yet at boot): exit 1.
  if (!service &&
      service.error().message.starts_with(densemap::server::MapService::kAnotherServer)) {
    return fail(service.error().message, 2);
  }
  if (!service) return fail("DDS: " + service.error().message);
  (*pipeline)->start();
  (*service)->start();
  spdlog::info("running on DDS domain {}, interface {}{}; {} backend at {} m, {} threads{}",
               service_options.domain_id, service_options.network_interface,
               service_options.security ? " with DDS Security" : "", config->map().backend(),
               options->resolution_m, options->threads,
               service_options.ros2 ? "; ROS 2 face on" : "");

  // systemd (Type=notify): ready now; with WatchdogSec, a WATCHDOG=1 every half period while the
  // publish thread goes round (a wedged server stops pinging and systemd restarts it).
  notifySystemd("READY=1\nSTATUS=mapping");
  std::uint64_t watchdog_us = 0;
#ifdef DENSEMAP_HAVE_SYSTEMD
  if (sd_watchdog_enabled(0, &watchdog_us) <= 0) watchdog_us = 0;
#endif
  int received = 0;
  while (true) {
    if (watchdog_us == 0) {
      sigwait(&signals, &received);
      break;
    }
    const std::uint64_t half = watchdog_us / 2;
    const timespec timeout{static_cast<time_t>(half / 1'000'000),
                           static_cast<long>(half % 1'000'000 * 1000)};
    const int sig = sigtimedwait(&signals, nullptr, &timeout);
    if (sig > 0) {
      received = sig;
      break;
    }
    const auto since = std::chrono::steady_clock::now() - (*service)->heartbeat();
    if (since < std::chrono::seconds(5)) notifySystemd("WATCHDOG=1");
  }
  notifySystemd("STOPPING=1");
  spdlog::info("{}: stopping", received == SIGINT ? "SIGINT" : "SIGTERM");
  (*service)->stop();   // no more scans or requests
  (*pipeline)->stop();  // finishes the scan in flight
  if (!snapshot.empty()) {
    auto saved = (*service)->save();
    if (!saved) {
      // The map must not be lost with the process (issue 28, item 5): a rescue copy goes to the
      // first place that takes it, and the log says where.
      spdlog::error("shutdown snapshot: {}", saved.error().message);
      const std::string name = "densemap-rescue-" + std::to_string(::getpid()) + ".dmap";
      std::error_code ec;  // current_path() throws when the working directory is gone
      for (const std::filesystem::path& dir :
           {service_options.export_dir, std::filesystem::current_path(ec),
            std::filesystem::path("/var/tmp")}) {
        if (dir.empty()) continue;
        std::filesystem::create_directories(dir, ec);
        if (auto rescued = (*service)->save(dir / name); rescued) {
          return fail("the map (version " + std::to_string((*pipeline)->view()->version()) +
                      ") was saved to " + (dir / name).string() + " instead: move it to " +
                      snapshot.string() + " to resume it");
        }
      }
      return fail("shutdown snapshot: no rescue copy could be written either: the map is lost");
    }
    spdlog::info("saved {} ({} bytes, version {})", snapshot.string(), *saved,
                 (*pipeline)->view()->version());
  }
  const auto c = (*pipeline)->counters();
  spdlog::info("received {}, integrated {}, dropped {}, rejected {}", c.received, c.integrated,
               c.dropped, c.rejected);
  return 0;
}

int main(int argc, char** argv) {
  return densemap::cli::guardedMain("densemap-server", [&] { return runMain(argc, argv); });
}
