#pragma once

// The brute-force reference for the Mapper's distance field (distance_field_*_test.cpp).
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <random>
#include <string>
#include <vector>

#include "densemap/geometry/voxel_grid.hpp"
#include "densemap/mapper/mapper.hpp"

namespace densemap::test {

/// Squared distances (cells^2) to the nearest occupied cell over the occupied cells' bounding
/// box grown by the radius, by stamping each occupied cell's ball.
struct Reference {
  std::array<int, 3> lo{}, size{};
  std::vector<std::uint32_t> d2;
  std::uint32_t none = 0;
  [[nodiscard]] std::size_t at(int x, int y, int z) const {
    return static_cast<std::size_t>(x - lo[0]) +
           static_cast<std::size_t>(size[0]) *
               (static_cast<std::size_t>(y - lo[1]) +
                static_cast<std::size_t>(size[1]) * static_cast<std::size_t>(z - lo[2]));
  }
};

inline Reference bruteForce(const std::vector<VoxelKey>& occupied, int radius,
                            std::uint32_t radius2) {
  Reference ref;
  ref.none = radius2 + 1;
  std::array<int, 3> hi{};
  ref.lo = {65536, 65536, 65536};
  hi = {-1, -1, -1};
  for (const VoxelKey& k : occupied) {
    for (int a = 0; a < 3; ++a) {
      ref.lo[a] = std::min(ref.lo[a], k[a] - radius - 1);
      hi[a] = std::max(hi[a], k[a] + radius + 1);
    }
  }
  for (int a = 0; a < 3; ++a) ref.size[a] = hi[a] - ref.lo[a] + 1;
  ref.d2.assign(static_cast<std::size_t>(ref.size[0]) * ref.size[1] * ref.size[2], ref.none);
  for (const VoxelKey& k : occupied) {
    for (int dz = -radius; dz <= radius; ++dz) {
      for (int dy = -radius; dy <= radius; ++dy) {
        for (int dx = -radius; dx <= radius; ++dx) {
          const auto d2 = static_cast<std::uint32_t>(dx * dx + dy * dy + dz * dz);
          if (d2 > radius2) continue;
          std::uint32_t& v = ref.d2[ref.at(k.x + dx, k.y + dy, k.z + dz)];
          v = std::min(v, d2);
        }
      }
    }
  }
  return ref;
}

/// Checks every cell of the reference box whose reference is finite, and as many others
/// (random cells of the box), against mapper.distance().
inline void expectEqualsBruteForce(const Mapper& mapper, double max_distance,
                                   const std::string& what) {
  const double res = mapper.resolution();
  const VoxelGrid grid(res);
  std::vector<VoxelKey> occupied;
  mapper.forEachCell(CellFilter::kOccupied,
                     [&](const Point3f& c, float) { occupied.push_back(*grid.pointToKey(c)); });
  ASSERT_FALSE(occupied.empty()) << what;
  const double cells = max_distance / res;
  const auto radius2 = static_cast<std::uint32_t>(std::floor(cells * cells * (1 + 1e-9)));
  const int radius = static_cast<int>(std::floor(std::sqrt(static_cast<double>(radius2))));
  const Reference ref = bruteForce(occupied, radius, radius2);
  std::vector<float> xyz;
  std::vector<float> want;
  std::mt19937 rng(5);
  std::uniform_real_distribution<double> pick(0.0, 1.0);
  const double finite_share =
      static_cast<double>(
          std::count_if(ref.d2.begin(), ref.d2.end(), [&](auto v) { return v < ref.none; })) /
      static_cast<double>(ref.d2.size());
  for (int z = ref.lo[2]; z < ref.lo[2] + ref.size[2]; ++z) {
    for (int y = ref.lo[1]; y < ref.lo[1] + ref.size[1]; ++y) {
      for (int x = ref.lo[0]; x < ref.lo[0] + ref.size[0]; ++x) {
        const std::uint32_t d2 = ref.d2[ref.at(x, y, z)];
        if (d2 == ref.none && pick(rng) > finite_share) continue;
        const Point3f c =
            grid.keyToPoint(VoxelKey{static_cast<std::uint16_t>(x), static_cast<std::uint16_t>(y),
                                     static_cast<std::uint16_t>(z)});
        xyz.insert(xyz.end(), {c.x(), c.y(), c.z()});
        want.push_back(d2 == ref.none
                           ? static_cast<float>(max_distance)
                           : static_cast<float>(std::sqrt(static_cast<double>(d2)) * res));
      }
    }
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
