#include "densemap/pipeline/map_queries.hpp"

#include <gtest/gtest.h>

#include "densemap/map/grid_map.hpp"

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

}  // namespace
}  // namespace densemap
