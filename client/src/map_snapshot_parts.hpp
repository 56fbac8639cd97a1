#pragma once

// MapSnapshot's inside, for the client's files that make one (client_map.cpp) and for the
// tests' access (client/testing).
#include <cstdint>
#include <memory>

#include "densemap/client/map_snapshot.hpp"
#include "densemap/map/grid_map.hpp"

namespace densemap {

struct MapSnapshot::Impl {
  std::unique_ptr<GridMap> map;
  std::uint64_t version = 0;
  std::vector<std::pair<std::string, std::int64_t>> last_stamps;
};

struct MapSnapshotAccess {
  static MapSnapshot make(std::unique_ptr<GridMap> map, std::uint64_t version,
                          std::vector<std::pair<std::string, std::int64_t>> last_stamps = {}) {
    return MapSnapshot(std::make_unique<MapSnapshot::Impl>(MapSnapshot::Impl{
        .map = std::move(map), .version = version, .last_stamps = std::move(last_stamps)}));
  }
  static const GridMap& grid(const MapSnapshot& snapshot) { return *snapshot.impl_->map; }
};

}  // namespace densemap
