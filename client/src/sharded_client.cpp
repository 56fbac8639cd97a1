#include "densemap/client/sharded_client.hpp"

#include <algorithm>
#include <limits>
#include <string>

#include "densemap/geometry/block_layout.hpp"
#include "densemap/geometry/voxel_grid.hpp"

namespace densemap {
namespace {

bool overlap(const std::pair<Point3f, Point3f>& a, const std::pair<Point3f, Point3f>& b) {
  return (a.first.array() < b.second.array()).all() && (b.first.array() < a.second.array()).all();
}

}  // namespace

ShardedClient::ShardedClient(std::vector<Shard> shards, double resolution)
    : shards_(std::move(shards)), resolution_(resolution) {}
ShardedClient::~ShardedClient() = default;

Expected<std::unique_ptr<ShardedClient>> ShardedClient::create(
    const std::vector<ClientOptions>& shards) {
  if (shards.empty() || shards.size() > kMaxShards) {
    return makeError("sharded client: 1 .. " + std::to_string(kMaxShards) + " shards");
  }
  std::vector<Shard> connected;
  double resolution = 0.0;
  for (std::size_t i = 0; i < shards.size(); ++i) {
    const std::string which = "shard " + std::to_string(i) + " (DDS domain " +
                              std::to_string(shards[i].domain_id) + "): ";
    auto client = Client::create(shards[i]);
    if (!client) return makeError(which + client.error().message);
    if (auto ok = (*client)->waitForServer(); !ok) return makeError(which + ok.error().message);
    auto manifest = (*client)->manifest();
    if (!manifest) return makeError(which + manifest.error().message);
    if (i == 0) resolution = manifest->resolution;
    if (manifest->resolution != resolution) {
      return makeError(which + "its resolution differs from shard 0's");
    }
    if (!manifest->bounds && shards.size() > 1) {
      return makeError(which + "has no map.bounds, so it holds all of space beside the others");
    }
    for (std::size_t j = 0; j < connected.size(); ++j) {
      if (manifest->bounds && overlap(*manifest->bounds, *connected[j].bounds)) {
        return makeError(which + "its box overlaps shard " + std::to_string(j) + "'s");
      }
    }
    connected.push_back({std::move(*client), manifest->bounds});
  }
  return std::unique_ptr<ShardedClient>(new ShardedClient(std::move(connected), resolution));
}

std::optional<std::size_t> ShardedClient::ownerOf(const Point3f& p) const {
  const VoxelGrid grid(resolution_);
  const auto key = grid.pointToKey(p);
  if (!key) return std::nullopt;
  const Point3f centre = block::centreOf(grid, block::blockOf(*key));
  for (std::size_t i = 0; i < shards_.size(); ++i) {
    const auto& box = shards_[i].bounds;
    if (!box || block::boxKeeps(box->first, box->second, centre)) return i;
  }
  return std::nullopt;
}

bool ShardedClient::mayTouch(std::size_t i, const Point3f& min, const Point3f& max) const {
  const auto& box = shards_[i].bounds;
  if (!box) return true;
  const auto margin = static_cast<float>(block::boxKeepMargin(resolution_));
  return (min.array() <= box->second.array() + margin).all() &&
         (box->first.array() - margin <= max.array()).all();
}

Expected<PointQueryAnswer> ShardedClient::queryPoints(std::span<const float> xyz_world) {
  if (xyz_world.size() % 3 != 0) {
    return makeError("points come as x y z: the count must be a multiple of 3");
  }
  const std::size_t n = xyz_world.size() / 3;
  PointQueryAnswer out;
  out.log_odds.assign(n, std::nullopt);
  out.states.assign(n, CellState::kUnknown);
  out.map_version = std::numeric_limits<std::uint64_t>::max();
  std::vector<std::vector<std::size_t>> of(shards_.size());
  for (std::size_t k = 0; k < n; ++k) {
    const Point3f p(xyz_world[3 * k], xyz_world[3 * k + 1], xyz_world[3 * k + 2]);
    if (const auto owner = ownerOf(p)) of[*owner].push_back(k);
  }
  bool asked = false;
  for (std::size_t i = 0; i < shards_.size(); ++i) {
    if (of[i].empty()) continue;
    std::vector<float> xyz;
    xyz.reserve(3 * of[i].size());
    for (std::size_t k : of[i]) xyz.insert(xyz.end(), &xyz_world[3 * k], &xyz_world[3 * k + 3]);
    auto answer = shards_[i].client->queryPoints(std::span<const float>(xyz));
    if (!answer) return makeError("shard " + std::to_string(i) + ": " + answer.error().message);
    if (answer->log_odds.size() != of[i].size() || answer->states.size() != of[i].size()) {
      return makeError("shard " + std::to_string(i) + " answered another number of points");
    }
    for (std::size_t j = 0; j < of[i].size(); ++j) {
      out.log_odds[of[i][j]] = answer->log_odds[j];
      out.states[of[i][j]] = answer->states[j];
    }
    out.map_version = std::min(out.map_version, answer->map_version);
    asked = true;
  }
  if (!asked) out.map_version = 0;
  return out;
}

Expected<BoxQueryAnswer> ShardedClient::queryBox(const Point3f& min, const Point3f& max,
                                                 std::uint32_t max_centers) {
  BoxQueryAnswer out;
  out.map_version = std::numeric_limits<std::uint64_t>::max();
  std::optional<std::uint64_t> cells;  // the box's cells, as every shard counts them
  for (std::size_t i = 0; i < shards_.size(); ++i) {
    if (!mayTouch(i, min, max)) continue;
    auto answer = shards_[i].client->queryBox(min, max, max_centers);
    if (!answer) return makeError("shard " + std::to_string(i) + ": " + answer.error().message);
    const std::uint64_t total = answer->occupied + answer->free + answer->unknown;
    if (cells && *cells != total) {
      return makeError("shard " + std::to_string(i) + " counted the box's cells differently");
    }
    cells = total;
    out.occupied += answer->occupied;
    out.free += answer->free;
    for (const Point3f& c : answer->occupied_centers) {
      if (out.occupied_centers.size() >= max_centers) break;
      out.occupied_centers.push_back(c);
    }
    out.map_version = std::min(out.map_version, answer->map_version);
  }
  if (!cells) {  // no shard keeps any of it: ask one for the box's size (and its checks)
    auto answer = shards_.front().client->queryBox(min, max, 0);
    if (!answer) return makeError("shard 0: " + answer.error().message);
    out.unknown = answer->occupied + answer->free + answer->unknown;
    out.map_version = answer->map_version;
    return out;
  }
  if (out.occupied + out.free > *cells) {
    return makeError("the shards hold more known cells than the box has: do their boxes overlap?");
  }
  out.unknown = *cells - out.occupied - out.free;
  return out;
}

Expected<RayQueryAnswer> ShardedClient::castRay(const Point3f& origin, const Point3f& direction,
                                                float max_range) {
  RayQueryAnswer out;
  out.map_version = std::numeric_limits<std::uint64_t>::max();
  for (std::size_t i = 0; i < shards_.size(); ++i) {
    auto answer = shards_[i].client->castRay(origin, direction, max_range);
    if (!answer) return makeError("shard " + std::to_string(i) + ": " + answer.error().message);
    if (answer->ray.hit && (!out.ray.hit || answer->ray.distance < out.ray.distance)) {
      out.ray = answer->ray;
    }
    out.map_version = std::min(out.map_version, answer->map_version);
  }
  return out;
}

}  // namespace densemap
