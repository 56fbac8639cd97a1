#pragma once

#include <CLI/CLI.hpp>

#include <cstdint>
#include <vector>

#include "densemap/client/client.hpp"

namespace densemap::cli {

/// `densemap query point | bbox | ray | distance | path`: the map's cells at points, cell counts
/// in a box, the first occupied cell along a ray, distances to the nearest obstacle, and
/// whether a robot of some radius can follow a path.
class QueryCommand {
 public:
  /// Adds the subcommands and their options to `app`.
  explicit QueryCommand(CLI::App& app);
  [[nodiscard]] bool parsed() const { return command_->parsed(); }
  /// The request's own rules (the server's, from core/query), before a server is looked for.
  [[nodiscard]] Expected<void> check() const;
  int run(Client& client);

 private:
  CLI::App* command_;
  CLI::App *point_, *box_, *ray_, *distance_, *path_;
  std::vector<float> coords_;
  std::uint32_t random_points_ = 0;
  float random_spread_ = 20.0F;
  std::vector<float> box_min_, box_max_;
  std::uint32_t centers_ = 0;
  std::vector<float> origin_, direction_;
  float range_ = 30.0F;
  std::vector<float> distance_coords_;
  bool unknown_occupied_ = false;
  bool interpolate_ = false;
  std::vector<float> path_coords_;
  float radius_ = 0.3F;
};

}  // namespace densemap::cli
