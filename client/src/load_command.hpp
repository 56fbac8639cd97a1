#pragma once

#include <CLI/CLI.hpp>

#include <memory>

#include "densemap/client/client.hpp"
#include "densemap/load/runner.hpp"

namespace densemap::cli {

/// `densemap load`: load tests from a scenario file (idl/densemap_load.proto).
class LoadCommand {
 public:
  /// Adds the subcommand and its options to `app`.
  explicit LoadCommand(CLI::App& app);
  [[nodiscard]] bool parsed() const { return command_->parsed(); }
  /// Runs it; `interface_given` says whether --interface was on the command line.
  int run(const ClientOptions& options, bool interface_given);

 private:
  /// The runner's options: the client's, the work directory, and a child process's arguments.
  [[nodiscard]] load::RunOptions runOptions(const ClientOptions& options) const;

  CLI::App* command_;
  std::string scenario_file_, out_dir_, work_dir_ = "/tmp/densemap-load";
  double duration_s_ = 0;
  bool ramp_ = false, processes_ = false, check_slo_ = false;
  int child_client_ = -1, child_ramp_step_ = -1;
  long long child_epoch_ns_ = 0;
  std::string child_out_, child_tracks_;
};

}  // namespace densemap::cli
