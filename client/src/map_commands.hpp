#pragma once

#include <CLI/CLI.hpp>

#include <optional>
#include <string>
#include <vector>

#include "densemap/client/client.hpp"

namespace densemap::cli {

/// The map as a whole: `snapshot` (fetch it and write it here), `save` (on the server's
/// machine), `status [--watch]`, `reset`, `clear-bbox`.
class MapCommands {
 public:
  /// Adds the subcommands and their options to `app`.
  explicit MapCommands(CLI::App& app);
  [[nodiscard]] bool parsed() const;
  /// The request's own rules (clear-bbox's box), before a server is looked for.
  [[nodiscard]] Expected<void> check() const;
  int run(Client& client);

 private:
  CLI::App *snapshot_, *save_, *status_, *reset_, *clear_;
  std::string snapshot_out_, save_path_;
  bool watch_ = false;
  std::vector<float> clear_min_, clear_max_;
};

/// `render`: a picture of a map file (top view or z-slice), offline.
class RenderCommand {
 public:
  explicit RenderCommand(CLI::App& app);
  [[nodiscard]] bool parsed() const { return command_->parsed(); }
  int run() const;

 private:
  CLI::App* command_;
  std::string in_, out_;
  std::optional<double> z_;
  int scale_ = 2;
  int min_occupied_ = 3;
};

}  // namespace densemap::cli
