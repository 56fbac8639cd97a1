#pragma once

// The brute-force reference for the Mapper's distance field (distance_field_*_test.cpp).
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <random>
#include <string>
#include <unordered_map>
#include <vector>

#include "densemap/geometry/voxel_grid.hpp"
#include "densemap/mapper/mapper.hpp"

namespace densemap::test {

/// Squared distances (cells^2) to the nearest occupied cell, by stamping each occupied
/// cell's ball, in 8^3 blocks (only those the balls reach).
struct Reference {
  std::uint32_t none = 0;
  std::unordered_map<std::uint64_t, std::array<std::uint32_t, 512>> blocks;
  [[nodiscard]] std::uint32_t at(int x, int y, int z) const {
    const auto it = blocks.find(key(x, y, z));
    return it == blocks.end() ? none : it->second[index(x, y, z)];
  }
  [[nodiscard]] static std::uint64_t key(int x, int y, int z) {
    return static_cast<std::uint64_t>(x >> 3) | (static_cast<std::uint64_t>(y >> 3) << 13) |
           (static_cast<std::uint64_t>(z >> 3) << 26);
  }
  [[nodiscard]] static std::size_t index(int x, int y, int z) {
    return static_cast<std::size_t>((x & 7) | ((y & 7) << 3) | ((z & 7) << 6));
  }
};

inline Reference bruteForce(const std::vector<VoxelKey>& occupied, int radius,
                            std::uint32_t radius2) {
  Reference ref;
  ref.none = radius2 + 1;
  std::uint64_t last = ~std::uint64_t{0};
  std::array<std::uint32_t, 512>* block = nullptr;
  for (const VoxelKey& k : occupied) {
    for (int dz = -radius; dz <= radius; ++dz) {
      for (int dy = -radius; dy <= radius; ++dy) {
        for (int dx = -radius; dx <= radius; ++dx) {
          const int x = k.x + dx, y = k.y + dy, z = k.z + dz;
          if (x < 0 || y < 0 || z < 0 || x > 65535 || y > 65535 || z > 65535) continue;
          const auto d2 = static_cast<std::uint32_t>(dx * dx + dy * dy + dz * dz);
          if (d2 > radius2) continue;
          if (const std::uint64_t b = Reference::key(x, y, z); b != last) {
            last = b;
            auto [it, fresh] = ref.blocks.try_emplace(b);
            if (fresh) it->second.fill(ref.none);
            block = &it->second;
          }
          std::uint32_t& v = (*block)[Reference::index(x, y, z)];
          v = std::min(v, d2);
        }
      }
    }
  }
  return ref;
}

/// Checks every cell of the blocks the reference holds, and as many random cells of the map's
/// extent (beyond the maximum unless in those blocks), against mapper.distance().
inline void expectEqualsBruteForce(const Mapper& mapper, double max_distance,
                                   const std::string& what) {
  const double res = mapper.resolution();
  const VoxelGrid grid(res);
  std::vector<VoxelKey> occupied;
  std::array<int, 3> lo{65535, 65535, 65535}, hi{0, 0, 0};
  mapper.forEachCell(CellFilter::kOccupied, [&](const Point3f& c, float) {
    const VoxelKey k = *grid.pointToKey(c);
    occupied.push_back(k);
    for (int a = 0; a < 3; ++a) {
      lo[a] = std::min<int>(lo[a], k[a]);
      hi[a] = std::max<int>(hi[a], k[a]);
    }
  });
  ASSERT_FALSE(occupied.empty()) << what;
  const double cells = max_distance / res;
  const auto radius2 = static_cast<std::uint32_t>(std::floor(cells * cells * (1 + 1e-9)));
  const int radius = static_cast<int>(std::floor(std::sqrt(static_cast<double>(radius2))));
  const Reference ref = bruteForce(occupied, radius, radius2);
  std::vector<float> xyz;
  std::vector<float> want;
  auto add = [&](int x, int y, int z) {
    const std::uint32_t d2 = ref.at(x, y, z);
    const Point3f c =
        grid.keyToPoint(VoxelKey{static_cast<std::uint16_t>(x), static_cast<std::uint16_t>(y),
                                 static_cast<std::uint16_t>(z)});
    xyz.insert(xyz.end(), {c.x(), c.y(), c.z()});
    want.push_back(d2 == ref.none ? static_cast<float>(max_distance)
                                  : static_cast<float>(std::sqrt(static_cast<double>(d2)) * res));
  };
  for (const auto& [key, values] : ref.blocks) {
    const int bx = static_cast<int>(key & 0x1fff) * 8,
              by = static_cast<int>((key >> 13) & 0x1fff) * 8,
              bz = static_cast<int>((key >> 26) & 0x1fff) * 8;
    for (int i = 0; i < 512; ++i) add(bx + (i & 7), by + ((i >> 3) & 7), bz + (i >> 6));
  }
  std::mt19937 rng(5);
  const std::size_t sampled = want.size();
  for (std::size_t i = 0; i < sampled; ++i) {
    std::array<int, 3> c{};
    for (int a = 0; a < 3; ++a) {
      c[a] = std::uniform_int_distribution<int>(std::max(lo[a] - 2 * radius, 0),
                                                std::min(hi[a] + 2 * radius, 65535))(rng);
    }
    add(c[0], c[1], c[2]);
  }
  auto got = mapper.distance(xyz, {.nearest = false});
  ASSERT_TRUE(got) << got.error().message;
  std::size_t wrong = 0;
  for (std::size_t i = 0; i < want.size(); ++i) {
    if (got->distances[i] != want[i] && ++wrong <= 5) {
      ADD_FAILURE() << what << ": cell at " << xyz[3 * i] << " " << xyz[3 * i + 1] << " "
                    << xyz[3 * i + 2] << " has " << got->distances[i] << ", brute force "
                    << want[i];
    }
  }
  EXPECT_EQ(wrong, 0U) << what << " (" << want.size() << " cells)";
}

}  // namespace densemap::test
