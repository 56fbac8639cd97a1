#include "query_command.hpp"

#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <random>

#include "cli_support.hpp"
#include "densemap/map/sensor_model.hpp"
#include "densemap/query/map_queries.hpp"

namespace densemap::cli {
namespace {

/// `query point`: xyz triples, or --random N points in a cube (counts per state). The
/// arguments passed QueryCommand::check.
int queryPointsCommand(Client& client, std::vector<float> coords, std::uint32_t random_points,
                       float random_spread) {
  if (random_points > 0) {
    std::mt19937 generator(42);
    std::uniform_real_distribution<float> axis(-random_spread, random_spread);
    coords.resize(std::size_t{random_points} * 3);
    for (float& c : coords) c = axis(generator);
    const auto t0 = std::chrono::steady_clock::now();
    auto answer = client.queryPoints(std::span<const float>(coords));
    if (!answer) return fail(answer.error().message);
    std::size_t counts[3] = {0, 0, 0};
    for (const auto state : answer->states) ++counts[std::min(2, static_cast<int>(state))];
    std::printf(
        "%u points: unknown %zu, free %zu, occupied %zu (map version %llu) in %.0f ms\n",
        random_points, counts[0], counts[1], counts[2],
        static_cast<unsigned long long>(answer->map_version),
        std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - t0).count());
    return 0;
  }
  auto answer = client.queryPoints(std::span<const float>(coords));
  if (!answer) return fail(answer.error().message);
  const char* names[] = {"unknown", "free", "occupied"};
  for (std::size_t i = 0; i < answer->states.size(); ++i) {
    std::printf("%g %g %g: %s", coords[3 * i], coords[3 * i + 1], coords[3 * i + 2],
                names[static_cast<int>(answer->states[i])]);
    if (answer->log_odds[i])
      std::printf(" (log-odds %.4f, p %.3f)", *answer->log_odds[i],
                  SensorModel::probability(*answer->log_odds[i]));
    std::printf("\n");
  }
  std::printf("map version %llu\n", static_cast<unsigned long long>(answer->map_version));
  return 0;
}

Point3f point3(const std::vector<float>& v) { return {v[0], v[1], v[2]}; }

int queryDistancesCommand(Client& client, const std::vector<float>& coords,
                          const DistanceQueryOptions& options) {
  auto a = client.queryDistances(coords, options);
  if (!a) return fail(a.error().message);
  for (std::size_t i = 0; i < a->distances.size(); ++i) {
    std::printf("%g %g %g: %.3f m", coords[3 * i], coords[3 * i + 1], coords[3 * i + 2],
                a->distances[i]);
    if (std::isnan(a->nearest[3 * i])) {
      std::printf(" (nothing within %.3g m)\n", a->max_distance);
      continue;
    }
    std::printf(", gradient %.3f %.3f %.3f, nearest obstacle %g %g %g\n", a->gradients[3 * i],
                a->gradients[3 * i + 1], a->gradients[3 * i + 2], a->nearest[3 * i],
                a->nearest[3 * i + 1], a->nearest[3 * i + 2]);
  }
  std::printf("map version %llu\n", static_cast<unsigned long long>(a->map_version));
  return 0;
}

int checkPathCommand(Client& client, const std::vector<float>& coords, float radius) {
  auto a = client.checkPath(coords, radius);
  if (!a) return fail(a.error().message);
  const char* names[] = {"unknown", "free", "occupied"};
  std::printf("%s: path of %.3f m, radius %g m (map version %llu)\n",
              names[static_cast<int>(a->state)], a->length_m, radius,
              static_cast<unsigned long long>(a->map_version));
  const auto line = [](const char* what, const std::optional<SweptConflict>& c) {
    if (!c) return;
    std::printf("  first %s cell %g %g %g at %.3f m along the path (segment %zu)\n", what,
                c->center.x(), c->center.y(), c->center.z(), c->arc_length, c->index);
  };
  line("occupied", a->occupied);
  line("unknown", a->unknown);
  // Exit status for scripts: 0 free, 3 occupied, 4 unknown.
  return a->state == CellState::kFree ? 0 : a->state == CellState::kOccupied ? 3 : 4;
}

}  // namespace

Expected<void> QueryCommand::check() const {
  if (point_->parsed()) {
    if (random_points_ > 0 && !coords_.empty()) return makeError("give xyz or --random, not both");
    if (random_points_ == 0 && (coords_.empty() || coords_.size() % 3 != 0)) {
      return makeError("point coordinates come in threes (or give --random N)");
    }
    return {};
  }
  if (box_->parsed()) return checkBox(point3(box_min_), point3(box_max_));
  if (ray_->parsed()) return checkRay(point3(origin_), point3(direction_), range_);
  if (distance_->parsed()) return checkPointCoordinates(distance_coords_.size());
  if (path_->parsed()) {
    if (path_coords_.empty() || path_coords_.size() % 3 != 0) {
      return makeError("path vertices come in threes (x y z ...)");
    }
    if (!(radius_ >= 0)) return makeError("--radius must be >= 0");
  }
  return {};
}

QueryCommand::QueryCommand(CLI::App& app) {
  command_ = app.add_subcommand("query", "Query the map");
  command_->require_subcommand(1);
  point_ = command_->add_subcommand("point", "Occupancy at points");
  point_->add_option("xyz", coords_, "x y z [x y z ...]");
  point_
      ->add_option("--random", random_points_,
                   "Instead of xyz: N points drawn uniformly (fixed seed) within --spread of the "
                   "origin on each axis, in one request; prints the counts per state (load and "
                   "request-budget tests)")
      ->check(CLI::Range(1U, 50'000'000U));
  point_->add_option("--spread", random_spread_, "Half-size of --random's cube, m")
      ->check(CLI::Range(0.0F, 10000.0F))
      ->capture_default_str();
  box_ = command_->add_subcommand("bbox", "Cell counts in a box");
  box_->add_option("--min", box_min_, "x y z")->required()->expected(3);
  box_->add_option("--max", box_max_, "x y z")->required()->expected(3);
  box_->add_option("--centers", centers_, "Return up to this many occupied cell centres");
  ray_ = command_->add_subcommand("ray", "First occupied cell along a ray");
  ray_->add_option("--origin", origin_, "x y z")->required()->expected(3);
  ray_->add_option("--direction", direction_, "x y z")->required()->expected(3);
  ray_->add_option("--range", range_, "Max range, m")->capture_default_str();
  distance_ = command_->add_subcommand(
      "distance",
      "Distance to the nearest obstacle, gradient and nearest obstacle at points "
      "(the server's distance field: config esdf)");
  distance_->add_option("xyz", distance_coords_, "x y z [x y z ...]")->required();
  distance_->add_flag("--unknown-occupied", unknown_occupied_, "Count unknown cells as obstacles");
  distance_->add_flag("--interpolate", interpolate_,
                      "Trilinear between the cell centres around each point");
  path_ = command_->add_subcommand(
      "path",
      "Whether a robot of --radius can follow a path: every cell within the radius of "
      "the polyline counts (exit 0 free, 3 occupied, 4 unknown)");
  path_->add_option("xyz", path_coords_, "x y z x y z ... (the vertices)")->required();
  path_->add_option("--radius", radius_, "The robot's radius, m")->capture_default_str();
}

int QueryCommand::run(Client& client) {
  if (point_->parsed()) return queryPointsCommand(client, coords_, random_points_, random_spread_);
  if (distance_->parsed()) {
    return queryDistancesCommand(
        client, distance_coords_,
        {.unknown_as_occupied = unknown_occupied_, .interpolate = interpolate_, .nearest = true});
  }
  if (path_->parsed()) return checkPathCommand(client, path_coords_, radius_);
  if (box_->parsed()) {
    auto a = client.queryBox(point3(box_min_), point3(box_max_), centers_);
    if (!a) return fail(a.error().message);
    std::printf("occupied %llu, free %llu, unknown %llu (map version %llu)\n",
                static_cast<unsigned long long>(a->occupied),
                static_cast<unsigned long long>(a->free),
                static_cast<unsigned long long>(a->unknown),
                static_cast<unsigned long long>(a->map_version));
    for (const auto& c : a->occupied_centers) std::printf("  %g %g %g\n", c.x(), c.y(), c.z());
    return 0;
  }
  auto a = client.castRay(point3(origin_), point3(direction_), range_);
  if (!a) return fail(a.error().message);
  if (a->ray.hit) {
    std::printf("hit at %g %g %g, %.3f m (map version %llu)\n", a->ray.hit_center.x(),
                a->ray.hit_center.y(), a->ray.hit_center.z(), a->ray.distance,
                static_cast<unsigned long long>(a->map_version));
  } else {
    std::printf("no occupied cell within %g m (map version %llu)\n", range_,
                static_cast<unsigned long long>(a->map_version));
  }
  return 0;
}

}  // namespace densemap::cli
