#include "densemap/query/map_queries.hpp"

#include <gtest/gtest.h>

#include <cmath>
#include <limits>
#include <random>

#include "densemap/map/grid_map.hpp"
#include "densemap/query/block_accessor.hpp"

namespace densemap {
namespace {

std::shared_ptr<const MapView> wallView() {
  GridMap map(0.1, SensorModel{});
  // A free corridor along +x ending in an occupied wall at x in [2.0, 2.1).
  for (float x = 0.05F; x < 2.0F; x += 0.1F)
    map.setLogOdds(*map.grid().pointToKey({x, 0.05F, 0.05F}), -1.0F);
  for (float y = -0.45F; y < 0.5F; y += 0.1F)
    map.setLogOdds(*map.grid().pointToKey({2.05F, y, 0.05F}), 2.0F);
  return MapView::fromMap(map, 7);
}

TEST(MapQueries, RayStopsAtTheFirstOccupiedCell) {
  const auto view = wallView();
  auto hit = castRay(*view, Point3f(0.05F, 0.05F, 0.05F), Point3f(1, 0, 0), 10.0F);
  ASSERT_TRUE(hit);
  EXPECT_TRUE(hit->hit);
  EXPECT_NEAR(hit->hit_center.x(), 2.05F, 1e-5);
  EXPECT_NEAR(hit->distance, 2.0F, 1e-5);
  auto miss = castRay(*view, Point3f(0.05F, 0.05F, 0.05F), Point3f(-1, 0, 0), 10.0F);
  ASSERT_TRUE(miss);
  EXPECT_FALSE(miss->hit);
  auto short_ray = castRay(*view, Point3f(0.05F, 0.05F, 0.05F), Point3f(1, 0, 0), 1.0F);
  EXPECT_FALSE(short_ray->hit);
  EXPECT_FALSE(castRay(*view, Point3f(0, 0, 0), Point3f(0, 0, 0), 1.0F));
  EXPECT_FALSE(castRay(*view, Point3f(0, 0, 0), Point3f(1, 0, 0), std::nanf("")));
}

TEST(MapQueries, BoxCountsCellsByStateAndRefusesBadBoxes) {
  const auto view = wallView();
  auto box = queryBox(*view, Point3f(0.0F, 0.0F, 0.0F), Point3f(2.19F, 0.09F, 0.09F), 1000, 10);
  ASSERT_TRUE(box);
  EXPECT_EQ(box->free, 20U);
  EXPECT_EQ(box->occupied, 1U);
  EXPECT_EQ(box->unknown, 1U);
  ASSERT_EQ(box->occupied_centers.size(), 1U);
  EXPECT_FALSE(queryBox(*view, Point3f(1, 1, 1), Point3f(0, 2, 2), 1000, 10));  // inverted
  EXPECT_FALSE(queryBox(*view, Point3f(-100, -100, -100), Point3f(100, 100, 100), 1000000, 10));
  EXPECT_FALSE(queryBox(*view, Point3f(0, 0, 0), Point3f(1, 1, std::nanf("")), 1000, 10));
}

// A ray request whose tiny range crosses voxel borders at
// denormal coordinates must end (it hung a query thread).
TEST(MapQueries, ATinyRayAcrossVoxelBordersEnds) {
  const auto view = wallView();
  auto r = castRay(*view, Point3f(1.2432865e-07F, 1.7622532e-38F, 1.7540580e-38F),
                   Point3f(0.0F, -0.5F, -67161704.0F), 6.6298237e-24F);
  ASSERT_TRUE(r) << r.error().message;  // it ends: the ray has no voxel to walk
  EXPECT_FALSE(r->hit);
}

// The point query lives with the box and ray queries (the server only wraps it).
TEST(MapQueries, PointsGetTheirCellsAndUnknownForNonFiniteOrFarPoints) {
  const auto view = wallView();
  const float inf = std::numeric_limits<float>::infinity();
  const std::vector<float> xyz = {0.55F, 0.05F, 0.05F, 2.05F,         0.05F, 0.05F,
                                  5.0F,  5.0F,  5.0F,  std::nanf(""), 0,     0,
                                  inf,   0,     0,     1e30F,         0,     0};
  auto r = queryPoints(*view, xyz);
  ASSERT_TRUE(r) << r.error().message;
  ASSERT_EQ(r->states.size(), 6U);
  EXPECT_EQ(r->log_odds[0], -1.0F);
  EXPECT_EQ(r->states[0], static_cast<std::uint8_t>(CellState::kFree));
  EXPECT_EQ(r->log_odds[1], 2.0F);
  EXPECT_EQ(r->states[1], static_cast<std::uint8_t>(CellState::kOccupied));
  for (std::size_t i = 2; i < 6; ++i) {
    EXPECT_TRUE(std::isnan(r->log_odds[i])) << i;
    EXPECT_EQ(r->states[i], static_cast<std::uint8_t>(CellState::kUnknown)) << i;
  }
  EXPECT_FALSE(queryPoints(*view, std::vector<float>{1, 2}));
  auto many = queryPoints(*view, std::vector<float>(30, 0.5F), 9);
  ASSERT_FALSE(many);
  EXPECT_NE(many.error().message.find("more than 9"), std::string::npos);
}

}  // namespace
}  // namespace densemap

namespace densemap {
namespace {

// The accessor's cached block gives what the view gives, cell by cell, on a walk that stays in
// a block, crosses into known and unknown blocks and comes back (the cache must follow).
TEST(BlockAccessor, EveryCellAsTheViewHasIt) {
  GridMap map(0.1, SensorModel{});
  std::mt19937 rng(9);
  std::uniform_int_distribution<int> coord(32768 - 12, 32768 + 12);
  std::uniform_real_distribution<float> value(-3.0F, 3.0F);
  for (int i = 0; i < 3000; ++i) {
    map.setLogOdds(
        VoxelKey{static_cast<std::uint16_t>(coord(rng)), static_cast<std::uint16_t>(coord(rng)),
                 static_cast<std::uint16_t>(coord(rng))},
        value(rng));
  }
  const auto view = MapView::fromMap(map, 1);
  BlockAccessor cells(*view);
  std::size_t known = 0;
  VoxelKey k{32768, 32768, 32768};
  std::uniform_int_distribution<int> step(-1, 1), jump(0, 20);
  for (int i = 0; i < 20000; ++i) {
    if (jump(rng) == 0) {                       // elsewhere now and then: another block, maybe none
      const int far = jump(rng) < 5 ? 100 : 0;  // a block with no cells, or back
      k = {static_cast<std::uint16_t>(coord(rng) + far), static_cast<std::uint16_t>(coord(rng)),
           static_cast<std::uint16_t>(coord(rng))};
    } else {
      k.x = static_cast<std::uint16_t>(k.x + step(rng));
      k.y = static_cast<std::uint16_t>(k.y + step(rng));
    }
    const auto expected = view->logOdds(k);
    ASSERT_EQ(cells.logOdds(k), expected) << i;
    known += expected ? 1 : 0;
  }
  EXPECT_GT(known, 500U);
  EXPECT_LT(known, 19500U);
}

}  // namespace
}  // namespace densemap
