#include "load_command.hpp"

#include <cstdio>
#include <cstdlib>
#include <fstream>

#include "densemap/load/report.hpp"
#include "densemap/load/runner.hpp"

namespace densemap::cli {
namespace {

int fail(const std::string& message) {
  std::fprintf(stderr, "densemap load: error: %s\n", message.c_str());
  return 1;
}

void writeReport(const std::filesystem::path& file, const std::string& text) {
  std::ofstream out(file);
  out << text;
}

}  // namespace

LoadCommand::LoadCommand(CLI::App& app) {
  command_ = app.add_subcommand(
      "load",
      "Load test: sensor streams, query clients and late joiners from a scenario "
      "(idl/densemap_load.proto; examples in config/load/), against a running server");
  command_->add_option("--scenario", scenario_file_, "Scenario file (text format)")->required();
  command_->add_option("--out", out_dir_,
                       "Directory for report.md, load.json and load.png (ramp: ramp.json, "
                       "ramp.png); default WORK_DIR/NAME");
  command_->add_option("--work-dir", work_dir_, "Simulated datasets and scratch files")
      ->capture_default_str();
  command_->add_option("--duration", duration_s_, "Override the scenario's duration_s (s)")
      ->check(CLI::Range(1.0, load::kMaxDurationS));
  command_->add_flag("--ramp", ramp_,
                     "Ramp mode: more sensors or clients step by step (the scenario's ramp "
                     "block) until the SLO breaks; reports the knee");
  command_->add_flag("--processes", processes_,
                     "Run each query client in its own process (default: threads of this one)");
  command_->add_flag("--check-slo", check_slo_, "Exit 3 when the run breaks the scenario's SLO");
  // A child query-client process (--processes); not for users.
  command_->add_option("--child-client", child_client_)->group("");
  command_->add_option("--child-epoch-ns", child_epoch_ns_)->group("");
  command_->add_option("--child-out", child_out_)->group("");
  command_->add_option("--child-tracks", child_tracks_)->group("");
  command_->add_option("--child-ramp-step", child_ramp_step_)->group("");
}

namespace {

/// One run of the scenario: the report (tables, SLO, the soak's timeline), load.json and
/// load.png in `out`. Exit 3 when --check-slo and the SLO broke, or a soak failed.
int runOnce(const load::Scenario& scenario, const load::RunOptions& run,
            const std::filesystem::path& out, bool check_slo) {
  auto result = load::runScenario(scenario, run);
  if (!result) return fail(result.error().message);
  std::string report = "# " + scenario.name + "\n\n" + load::tables(*result);
  const load::SloVerdict slo = load::checkSlo(*result, scenario.slo);
  report += "\nSLO " + std::string(slo.kept ? "kept" : "broken: " + slo.broken) + "\n";
  int code = check_slo && !slo.kept ? 3 : 0;
  if (scenario.soak) {
    const load::SoakVerdict soak = load::checkSoak(*result, *scenario.soak, scenario.slo);
    report += "\n" + load::timelineTable(*result, scenario) + "\n" + load::soakSummary(soak);
    if (!soak.passed) code = 3;
  }
  std::printf("%s", report.c_str());
  writeReport(out / "report.md", report);
  if (auto ok = load::writeJson(out / "load.json", *result, scenario); !ok) {
    return fail(ok.error().message);
  }
  if (auto ok = load::writeRunChart(out / "load.png", *result, scenario); !ok) {
    return fail(ok.error().message);
  }
  std::printf("wrote %s, %s, %s\n", (out / "report.md").c_str(), (out / "load.json").c_str(),
              (out / "load.png").c_str());
  return code;
}

/// A ramp step's figures: the count under test, its SLO verdict, CPU, scans and queries per s.
load::RampStepResult stepResult(const load::RunResult& result, const load::Scenario& s,
                                std::uint32_t count) {
  load::RampStepResult r;
  r.count = count;
  r.slo = load::checkSlo(result, s.slo);
  r.cpu = load::cpuUse(result.usage, 0, s.duration_s);
  for (const auto& x : result.sensors) r.scans_per_s += static_cast<double>(x.seen);
  for (const auto& c : result.clients) {
    for (const auto a : c.answered) r.queries_per_s += static_cast<double>(a);
  }
  r.scans_per_s /= s.duration_s;
  r.queries_per_s /= s.duration_s;
  return r;
}

/// Ramp mode: step after step (the map reset between steps when the plan says so) until the
/// SLO breaks; the table, the knee, ramp.json and ramp.png in `out`.
int runRamp(const load::Scenario& scenario, const load::RunOptions& run,
            const ClientOptions& options, const std::filesystem::path& out) {
  const load::RampPlan& ramp = *scenario.ramp;
  std::vector<load::RampStepResult> steps;
  std::unique_ptr<Client> operator_client;
  for (std::uint32_t step = 0; step < ramp.max_steps; ++step) {
    const load::Scenario s = load::rampStep(scenario, step);
    if (ramp.reset_between_steps) {
      if (!operator_client) {
        auto c = Client::create(options);
        if (!c) return fail(c.error().message);
        operator_client = std::move(*c);
        if (auto ok = operator_client->waitForServer(); !ok) return fail(ok.error().message);
      }
      if (auto r = operator_client->reset(); !r) {
        return fail("reset before step " + std::to_string(step + 1) + ": " + r.error().message);
      }
    }
    load::RunOptions step_run = run;
    step_run.child_args.insert(step_run.child_args.end(),
                               {"--child-ramp-step", std::to_string(step)});
    const std::uint32_t count = load::rampCount(ramp, step);
    std::fprintf(stderr, "load: ramp step %u: %u %s for %.0f s\n", step + 1, count,
                 ramp.vary_sensors ? "sensors" : "query clients", s.duration_s);
    auto result = load::runScenario(s, step_run);
    if (!result) return fail(result.error().message);
    const load::RampStepResult r = stepResult(*result, s, count);
    steps.push_back(r);
    std::fprintf(stderr, "load: step %u: e2e p99 %.1f ms, %llu dropped, SLO %s\n", step + 1,
                 r.slo.e2e.p99, static_cast<unsigned long long>(r.slo.dropped),
                 r.slo.kept ? "kept" : r.slo.broken.c_str());
    writeReport(out / ("step-" + std::to_string(count) + ".md"), load::tables(*result));
    (void)load::writeRampJson(out / "ramp.json", steps, scenario);
    if (!r.slo.kept) break;
  }
  const std::string report = "# " + scenario.name + " (ramp)\n\n" +
                             load::rampTable(steps, ramp.vary_sensors) + "\n" +
                             load::kneeSummary(steps, ramp.vary_sensors, scenario.slo);
  std::printf("%s", report.c_str());
  writeReport(out / "report.md", report);
  if (auto ok = load::writeRampJson(out / "ramp.json", steps, scenario); !ok) {
    return fail(ok.error().message);
  }
  if (auto ok = load::writeRampChart(out / "ramp.png", steps, scenario); !ok) {
    return fail(ok.error().message);
  }
  std::printf("wrote %s, %s, %s\n", (out / "report.md").c_str(), (out / "ramp.json").c_str(),
              (out / "ramp.png").c_str());
  return 0;
}

}  // namespace

load::RunOptions LoadCommand::runOptions(const ClientOptions& options) const {
  load::RunOptions run;
  run.client = options;
  run.work_dir = work_dir_;
  run.processes = processes_;
  std::error_code ec;
  run.self_exe = std::filesystem::read_symlink("/proc/self/exe", ec);
  // What a child query-client process (--processes) is started with: this command's options.
  run.child_args = {"--domain-id",  std::to_string(options.domain_id),
                    "--interface",  options.network_interface,
                    "--timeout-ms", std::to_string(options.timeout.count()),
                    "load",         "--scenario",
                    scenario_file_, "--work-dir",
                    work_dir_};
  if (const auto& s = options.security) {
    std::vector<std::string> flags;
    for (const dds::SecurityFileField& f : dds::kSecurityFileFields) {
      flags.insert(flags.end(), {dds::securityFlag(f), (*s).*f.member});
    }
    run.child_args.insert(run.child_args.begin(), flags.begin(), flags.end());
  }
  if (duration_s_ > 0) {
    run.child_args.insert(run.child_args.end(), {"--duration", std::to_string(duration_s_)});
  }
  return run;
}

int LoadCommand::run(const ClientOptions& options, bool interface_given) {
  // The participants bind the configured interface (loopback unless --interface says
  // otherwise); a CYCLONEDDS_URI could point them anywhere, so it must be chosen explicitly.
  const char* uri = std::getenv("CYCLONEDDS_URI");
  if (uri != nullptr && *uri != '\0' && !interface_given) {
    return fail(
        "CYCLONEDDS_URI is set; the load tool uses loopback only unless --interface is "
        "given explicitly (unset CYCLONEDDS_URI, or pass --interface)");
  }
  auto scenario = load::loadScenario(scenario_file_);
  if (!scenario) return fail(scenario.error().message);
  if (duration_s_ > 0) scenario->duration_s = duration_s_;
  if (ramp_ && !scenario->ramp) return fail(scenario_file_ + " has no ramp block");
  const load::RunOptions run = runOptions(options);
  if (child_client_ >= 0) {
    if (child_ramp_step_ >= 0 && scenario->ramp) {
      *scenario = load::rampStep(*scenario, static_cast<std::uint32_t>(child_ramp_step_));
    }
    const load::Clock::time_point epoch{std::chrono::nanoseconds(child_epoch_ns_)};
    return load::runChildClient(*scenario, static_cast<std::size_t>(child_client_), epoch,
                                child_tracks_, child_out_, run);
  }
  const std::filesystem::path out = out_dir_.empty()
                                        ? std::filesystem::path(work_dir_) / scenario->name
                                        : std::filesystem::path(out_dir_);
  std::error_code ec;
  std::filesystem::create_directories(out, ec);
  if (ec) return fail("cannot create " + out.string() + ": " + ec.message());
  if (auto ok = load::prepareData(*scenario, work_dir_); !ok) return fail(ok.error().message);
  std::fprintf(stderr, "load: %s on interface %s, domain %u; outputs in %s\n",
               scenario->name.c_str(), options.network_interface.c_str(), options.domain_id,
               out.string().c_str());
  return ramp_ ? runRamp(*scenario, run, options, out) : runOnce(*scenario, run, out, check_slo_);
}

}  // namespace densemap::cli
