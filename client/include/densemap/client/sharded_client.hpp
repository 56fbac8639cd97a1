#pragma once

#include <memory>
#include <optional>
#include <span>
#include <vector>

#include "densemap/client/client.hpp"

namespace densemap {

/// Queries across spatial shards (docs/fleet.md): servers whose map.bounds tile space, each on
/// its own DDS domain or with its own dds.instance, answered as one map. Each server's box comes
/// from its manifest; a cell belongs to the shard whose box holds its block's centre (the rule by
/// which a shard keeps blocks). Points go to the shard of their cell; a box goes to every shard
/// whose blocks it may touch and the counts add up; a ray goes to every shard and the nearest hit
/// wins (a shard's map is unknown outside its box, and rays pass unknown cells). The answer's
/// map_version is the oldest version among the shards that answered.
/// Thread-safety: one thread at a time, as Client.
class ShardedClient {
 public:
  /// At most this many shards.
  static constexpr std::size_t kMaxShards = 64;

  /// Connects to every shard and reads its manifest. Errors when a shard does not answer
  /// within its options' timeout, when the shards' resolutions differ, when two boxes overlap,
  /// or when a shard without a box is not the only one.
  [[nodiscard]] static Expected<std::unique_ptr<ShardedClient>> create(
      const std::vector<ClientOptions>& shards);
  ~ShardedClient();
  ShardedClient(const ShardedClient&) = delete;
  ShardedClient& operator=(const ShardedClient&) = delete;

  [[nodiscard]] std::size_t shards() const { return shards_.size(); }
  /// The shard that keeps the cell at `p`; none outside every box (or the addressable space).
  [[nodiscard]] std::optional<std::size_t> ownerOf(const Point3f& p) const;
  /// The shard's own client (status, fetchMap, scans).
  [[nodiscard]] Client& shard(std::size_t i) { return *shards_[i].client; }

  /// The cells at the points (x y z per point, metres); a point no shard keeps is unknown.
  [[nodiscard]] Expected<PointQueryAnswer> queryPoints(std::span<const float> xyz_world);
  /// Occupied, free and unknown cells of the box [min, max] over all shards, and up to
  /// `max_centers` occupied centres (as Client::queryBox).
  [[nodiscard]] Expected<BoxQueryAnswer> queryBox(const Point3f& min, const Point3f& max,
                                                  std::uint32_t max_centers = 0);
  /// The first occupied cell along the ray over all shards.
  [[nodiscard]] Expected<RayQueryAnswer> castRay(const Point3f& origin, const Point3f& direction,
                                                 float max_range);

 private:
  struct Shard {
    std::unique_ptr<Client> client;
    std::optional<std::pair<Point3f, Point3f>> bounds;
  };
  ShardedClient(std::vector<Shard> shards, double resolution);
  /// Whether shard i may keep cells of the box [min, max] (its box grown by its keep margin).
  [[nodiscard]] bool mayTouch(std::size_t i, const Point3f& min, const Point3f& max) const;

  std::vector<Shard> shards_;
  double resolution_;
};

}  // namespace densemap
