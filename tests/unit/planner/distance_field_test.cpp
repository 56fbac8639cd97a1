// The distance field against a brute-force reference: after every batch of random changes
// (cells made occupied, free or unknown, in scattered cells and in planes whose cells shadow
// each other), every cell within reach holds the squared distance to the nearest occupied
// cell found by trying every occupied cell.
#include "densemap/planner/distance_field.hpp"

#include <gtest/gtest.h>

#include <random>
#include <set>
#include <tuple>

#include "densemap/map/grid_map.hpp"
#include "densemap/planner/distance_slice.hpp"

namespace densemap {
namespace {

using Cell = std::tuple<int, int, int>;

/// The map, and the occupied cells as the reference sees them.
struct World {
  explicit World(double res) : map(res, SensorModel{}) { map.startLiveVersions(); }
  GridMap map;
  std::set<Cell> occupied;

  void set(const Cell& c, float v) {
    const auto [x, y, z] = c;
    map.setLogOdds(VoxelKey{static_cast<std::uint16_t>(x), static_cast<std::uint16_t>(y),
                            static_cast<std::uint16_t>(z)},
                   v);
    if (v > 0) {
      occupied.insert(c);
    } else {
      occupied.erase(c);
    }
  }
  void forget(const Cell& c) {
    const auto [x, y, z] = c;
    map.erase(VoxelKey{static_cast<std::uint16_t>(x), static_cast<std::uint16_t>(y),
                       static_cast<std::uint16_t>(z)});
    occupied.erase(c);
  }
  /// Ends the version and updates `field` from the blocks it wrote.
  DistanceUpdateStats publishTo(DistanceField& field) {
    std::vector<std::uint64_t> written;
    const auto view = MapView::advanceLive(map, 0, &written);
    return field.update(*view, written);
  }
};

/// Every cell of [lo, hi]^3 holds the brute-force squared distance; returns cells checked.
std::size_t expectBruteForce(const DistanceField& field, const World& w, int lo, int hi) {
  const auto r2 = static_cast<int>(field.radiusSquared());
  std::size_t wrong = 0;
  std::size_t checked = 0;
  for (int z = lo; z <= hi; ++z) {
    for (int y = lo; y <= hi; ++y) {
      for (int x = lo; x <= hi; ++x) {
        std::int64_t best = r2 + 1;
        for (const auto& [ox, oy, oz] : w.occupied) {
          const std::int64_t dx = x - ox, dy = y - oy, dz = z - oz;
          best = std::min(best, dx * dx + dy * dy + dz * dz);
        }
        const std::int64_t want = best > r2 ? DistanceField::kFar : best;
        const int got = field.distanceSquared(VoxelKey{static_cast<std::uint16_t>(x),
                                                       static_cast<std::uint16_t>(y),
                                                       static_cast<std::uint16_t>(z)});
        if (got != want && ++wrong <= 5) {
          ADD_FAILURE() << "cell " << x << " " << y << " " << z << ": field " << got
                        << ", brute force " << want;
        }
        ++checked;
      }
    }
  }
  EXPECT_EQ(wrong, 0U);
  return checked;
}

TEST(DistanceField, EqualsBruteForceAfterEveryBatchOfRandomChanges) {
  // 6 and 10 cells (one byte a cell), 16 cells (squared 256: two bytes a cell).
  for (const double max_distance : {0.6, 1.0, 1.6}) {
    World w(0.1);
    auto field = DistanceField::create(0.1, {.max_distance_m = max_distance});
    ASSERT_TRUE(field);
    std::mt19937 rng(11);
    // Cells 32760 .. 32791: across the key's sign boundary and across blocks.
    const int base = 32760;
    std::uniform_int_distribution<int> coord(base, base + 31);
    std::uniform_int_distribution<int> kind(0, 9);
    for (int round = 0; round < 9; ++round) {
      for (int i = 0; i < 60; ++i) {
        const Cell c{coord(rng), coord(rng), coord(rng)};
        const int k = kind(rng);
        if (k < 5) {
          w.set(c, 1.2F);
        } else if (k < 8) {
          w.set(c, -0.4F);
        } else {
          w.forget(c);
        }
      }
      // A wall that comes and goes: removals whose cells had many nearest neighbours.
      const int wx = coord(rng);
      const bool wall = round % 3 != 2;
      for (int z = base + 8; z < base + 24; ++z) {
        for (int y = base + 8; y < base + 24; ++y) w.set({wx, y, z}, wall ? 2.0F : -2.0F);
      }
      const auto stats = w.publishTo(*field);
      EXPECT_GT(stats.added + stats.removed, 0U);
      const int reach = field->radius() + 2;
      expectBruteForce(*field, w, base - reach, base + 31 + reach);
    }
    // Everything gone: every block of the field is freed.
    for (const Cell& c : std::set<Cell>(w.occupied)) w.forget(c);
    w.publishTo(*field);
    EXPECT_EQ(field->blocks(), 0U);
  }
}

TEST(DistanceField, AtTheEdgesOfTheKeyRange) {
  World w(0.2);
  auto field = DistanceField::create(0.2, {.max_distance_m = 1.0});
  ASSERT_TRUE(field);
  w.set({0, 0, 0}, 1.0F);
  w.set({3, 1, 0}, 1.0F);
  w.set({65535, 65535, 65535}, 1.0F);
  w.publishTo(*field);
  expectBruteForce(*field, w, 0, 9);
  World far(0.2);
  far.occupied = {{65535, 65535, 65535}};
  for (int z = 65526; z <= 65535; ++z) {
    for (int y = 65526; y <= 65535; ++y) {
      for (int x = 65526; x <= 65535; ++x) {
        const auto k = VoxelKey{static_cast<std::uint16_t>(x), static_cast<std::uint16_t>(y),
                                static_cast<std::uint16_t>(z)};
        const int d2 =
            (65535 - x) * (65535 - x) + (65535 - y) * (65535 - y) + (65535 - z) * (65535 - z);
        EXPECT_EQ(field->distanceSquared(k), d2 > 25 ? DistanceField::kFar : d2);
      }
    }
  }
}

TEST(DistanceField, NearestOccupiedIsOccupiedAndAtTheDistance) {
  World w(0.1);
  auto field = DistanceField::create(0.1, {.max_distance_m = 1.5});
  ASSERT_TRUE(field);
  std::mt19937 rng(3);
  std::uniform_int_distribution<int> coord(1000, 1040);
  for (int i = 0; i < 40; ++i) w.set({coord(rng), coord(rng), coord(rng)}, 1.0F);
  w.publishTo(*field);
  std::size_t found = 0;
  for (int z = 990; z <= 1050; z += 3) {
    for (int y = 990; y <= 1050; y += 3) {
      for (int x = 990; x <= 1050; x += 3) {
        const VoxelKey k{static_cast<std::uint16_t>(x), static_cast<std::uint16_t>(y),
                         static_cast<std::uint16_t>(z)};
        const auto d2 = field->distanceSquared(k);
        const auto nearest = field->nearestOccupied(k);
        ASSERT_EQ(nearest.has_value(), d2 != DistanceField::kFar);
        if (!nearest) continue;
        ++found;
        EXPECT_TRUE(w.occupied.contains({nearest->x, nearest->y, nearest->z}));
        const int dx = nearest->x - x, dy = nearest->y - y, dz = nearest->z - z;
        EXPECT_EQ(dx * dx + dy * dy + dz * dz, d2);
      }
    }
  }
  EXPECT_GT(found, 1000U);
}

TEST(DistanceField, RefusesMaximaItCannotHold) {
  EXPECT_FALSE(DistanceField::create(0.1, {.max_distance_m = 0.0}));
  EXPECT_FALSE(DistanceField::create(0.1, {.max_distance_m = -1.0}));
  EXPECT_FALSE(DistanceField::create(0.1, {.max_distance_m = std::nan("")}));
  EXPECT_FALSE(DistanceField::create(0.1, {.max_distance_m = 2.9}));
  EXPECT_FALSE(DistanceField::create(0.1, {.max_distance_m = 0.05}));
  const auto ok = DistanceField::create(0.2, {.max_distance_m = 2.0});
  ASSERT_TRUE(ok);
  EXPECT_EQ(ok->radiusSquared(), 100U);
  EXPECT_EQ(ok->radius(), 10);
}

}  // namespace
}  // namespace densemap

namespace densemap {
namespace {

TEST(DistanceSlice, LayerAndCostmapEqualBruteForce) {
  World w(0.1);
  auto field = DistanceField::create(0.1, {.max_distance_m = 0.8});
  ASSERT_TRUE(field);
  std::mt19937 rng(21);
  std::uniform_int_distribution<int> coord(32760, 32800);
  for (int i = 0; i < 200; ++i) {
    const Cell c{coord(rng), coord(rng), coord(rng)};
    w.set(c, i % 3 == 0 ? 1.5F : -0.7F);
  }
  w.publishTo(*field);
  const auto view = MapView::advanceLive(w.map);
  const double res = 0.1;
  for (const int layer : {32770, 32781, 32799}) {
    const double z = (layer - 32768 + 0.5) * res;
    auto bruteD2 = [&](int x, int y) {
      std::int64_t best = std::numeric_limits<std::int64_t>::max();
      for (const auto& [ox, oy, oz] : w.occupied) {
        const std::int64_t dx = x - ox, dy = y - oy, dz = layer - oz;
        best = std::min(best, dx * dx + dy * dy + dz * dz);
      }
      return best;
    };
    // The slice: exactly the layer's cells within 8 cells, each at its distance.
    const auto slice = distanceSlice(*field, z);
    std::size_t want = 0;
    for (int y = 32740; y < 32830; ++y) {
      for (int x = 32740; x < 32830; ++x) want += bruteD2(x, y) <= 64 ? 1 : 0;
    }
    EXPECT_EQ(slice.size(), want) << layer;
    for (const auto& p : slice) {
      const auto k = view->grid().pointToKey(Point3f(p[0], p[1], p[2]));
      ASSERT_TRUE(k);
      EXPECT_EQ(k->z, layer);
      EXPECT_FLOAT_EQ(
          p[3], static_cast<float>(std::sqrt(static_cast<double>(bruteD2(k->x, k->y))) * res));
    }
    // The costmap: 100 within 0.25 m (6 cells^2) of an occupied cell, 0 known, -1 unknown.
    const Costmap m = inflatedCostmap(*field, *view, z, 0.25);
    ASSERT_GT(m.width, 0U);
    std::size_t lethal = 0;
    for (std::uint32_t gy = 0; gy < m.height; ++gy) {
      for (std::uint32_t gx = 0; gx < m.width; ++gx) {
        const Point3f c(static_cast<float>(m.origin_x + (gx + 0.5) * res),
                        static_cast<float>(m.origin_y + (gy + 0.5) * res), static_cast<float>(z));
        const VoxelKey k = *view->grid().pointToKey(c);
        const std::int8_t got = m.data[static_cast<std::size_t>(gy) * m.width + gx];
        const std::int8_t expect = bruteD2(k.x, k.y) <= 6 ? 100 : view->logOdds(k) ? 0 : -1;
        ASSERT_EQ(got, expect) << layer << " at " << gx << " " << gy;
        lethal += got == 100 ? 1 : 0;
      }
    }
    EXPECT_GT(lethal, 0U) << layer;
  }
}

TEST(DistanceField, StoresOneByteACellUpTo15Cells) {
  const SensorModel model;
  GridMap map(0.2, model);
  for (int x = 0; x < 40; ++x) {
    for (int y = 0; y < 40; ++y)
      map.setLogOdds(*map.grid().pointToKey({0.2F * x, 0.2F * y, 0.1F}), 2.0F);
  }
  const auto view = MapView::fromMap(map, 1);
  auto narrow = DistanceField::create(0.2, {.max_distance_m = 3.0});  // 15 cells
  auto wide = DistanceField::create(0.2, {.max_distance_m = 3.2});    // 16 cells
  ASSERT_TRUE(narrow && wide);
  narrow->rebuild(*view);
  wide->rebuild(*view);
  ASSERT_GT(narrow->blocks(), 0U);
  // Per block: 512 bytes against 1024 (plus the same slot arrays).
  EXPECT_LT(narrow->memoryBytes(), wide->memoryBytes() * 6 / 10);
  std::size_t cells = 0;
  narrow->forEachFinite([&](const VoxelKey& k, std::uint16_t d2) {
    ++cells;
    if (d2 != wide->distanceSquared(k)) ADD_FAILURE() << "cell differs at " << d2;
  });
  EXPECT_GT(cells, 0U);
  EXPECT_EQ(narrow->distanceSquared(*map.grid().pointToKey({-3.1F, 0.1F, 0.1F})),
            DistanceField::kFar);
}

}  // namespace
}  // namespace densemap
