#include "densemap/sim/procedural_scenes.hpp"

#include <cmath>
#include <cstdlib>
#include <random>

#include "densemap/sim/octree_scene.hpp"
#include "densemap/sim/primitive_scene.hpp"

namespace densemap {
namespace {

using V3 = Eigen::Vector3d;

void addWallX(PrimitiveScene& s, double x0, double x1, double y, double height) {
  s.add(BoxShape{V3(x0, y - 0.1, 0), V3(x1, y + 0.1, height)});
}
void addWallY(PrimitiveScene& s, double y0, double y1, double x, double height) {
  s.add(BoxShape{V3(x - 0.1, y0, 0), V3(x + 0.1, y1, height)});
}

/// The benchmark scenes' 10 x 7 x 2 m frame: bounds and a floor.
constexpr double kRoomLength = 10, kRoomWidth = 7, kRoomHeight = 2;
std::unique_ptr<PrimitiveScene> benchmarkRoom() {
  auto scene = std::make_unique<PrimitiveScene>(Eigen::AlignedBox3d(
      V3(-0.2, -0.2, -0.1), V3(kRoomLength + 0.2, kRoomWidth + 0.2, kRoomHeight)));
  scene->add(BoxShape{V3(-0.2, -0.2, -0.1), V3(kRoomLength + 0.2, kRoomWidth + 0.2, 0)});  // floor
  return scene;
}

}  // namespace

SimScene makeIndoorScene(unsigned seed) {
  std::mt19937_64 rng(seed);
  std::uniform_real_distribution<double> u(0.0, 1.0);
  constexpr double kLength = 30, kWidth = 20, kHeight = 3;
  auto scene = std::make_unique<PrimitiveScene>(
      Eigen::AlignedBox3d(V3(-0.5, -0.5, -0.3), V3(kLength + 0.5, kWidth + 0.5, kHeight + 0.3)));
  scene->add(BoxShape{V3(-0.5, -0.5, -0.2), V3(kLength + 0.5, kWidth + 0.5, 0)});  // floor
  scene->add(BoxShape{V3(-0.5, -0.5, kHeight), V3(kLength + 0.5, kWidth + 0.5, kHeight + 0.2)});
  addWallX(*scene, 0, kLength, 0, kHeight);
  addWallX(*scene, 0, kLength, kWidth, kHeight);
  addWallY(*scene, 0, kWidth, 0, kHeight);
  addWallY(*scene, 0, kWidth, kLength, kHeight);
  // Corridor y in [8, 12]; its walls have a 1.2 m door into every room.
  for (const double y : {8.0, 12.0}) {
    for (double x = 0; x < kLength; x += 6) {
      const double door = x + 1.0 + u(rng) * 3.0;
      addWallX(*scene, x, door, y, kHeight);
      addWallX(*scene, door + 1.2, x + 6, y, kHeight);
    }
  }
  for (double x = 6; x < kLength; x += 6) {  // walls between rooms
    addWallY(*scene, 0, 8, x, kHeight);
    addWallY(*scene, 12, kWidth, x, kHeight);
  }
  // Furniture: desks, cabinets and a round table or pillar per room.
  for (double x = 0; x < kLength; x += 6) {
    for (const double y0 : {0.0, 12.0}) {
      for (int i = 0; i < 3; ++i) {
        const double w = 0.6 + u(rng) * 1.2, d = 0.5 + u(rng) * 0.8, h = 0.7 + u(rng) * 1.3;
        const double cx = x + 0.5 + u(rng) * (5.0 - w), cy = y0 + 0.8 + u(rng) * (6.4 - d);
        scene->add(BoxShape{V3(cx, cy, 0), V3(cx + w, cy + d, h)});
      }
      scene->add(CylinderShape{Eigen::Vector2d(x + 3.0, y0 + 4.0), 0.2 + u(rng) * 0.3, 0,
                               u(rng) < 0.5 ? 0.75 : kHeight});
    }
  }
  SimScene out{"indoor", std::move(scene), {}};
  for (double x = 1.5; x <= kLength - 1.5; x += 3.0) out.waypoints.emplace_back(x, 10.0, 1.2);
  return out;
}

SimScene makeOutdoorScene(unsigned seed, double length_m) {
  std::mt19937_64 rng(seed);
  std::uniform_real_distribution<double> u(0.0, 1.0);
  const double kLength = length_m;
  auto scene = std::make_unique<PrimitiveScene>(
      Eigen::AlignedBox3d(V3(-10, -40, -0.5), V3(kLength + 10, 40, 12)));
  scene->add(BoxShape{V3(-10, -40, -0.5), V3(kLength + 10, 40, 0)});  // ground
  for (const double side : {-1.0, 1.0}) {
    for (double x = -8; x < kLength + 8;) {  // buildings with gaps between them
      const double w = 8 + u(rng) * 12, depth = 10 + u(rng) * 15, h = 6 + u(rng) * 19;
      const double y_near = side * (10 + u(rng) * 3);
      const double y_far = y_near + side * depth;
      scene->add(
          BoxShape{V3(x, std::min(y_near, y_far), 0), V3(x + w, std::max(y_near, y_far), h)});
      x += w + 2 + u(rng) * 4;
    }
    for (double x = 2; x < kLength; x += 12 + u(rng) * 6) {  // poles
      scene->add(CylinderShape{Eigen::Vector2d(x, side * 7.5), 0.12, 0, 5 + u(rng) * 3});
    }
    for (double x = 6; x < kLength; x += 9 + u(rng) * 8) {  // trees
      const double trunk = 2 + u(rng) * 2;
      scene->add(CylinderShape{Eigen::Vector2d(x, side * 8.7), 0.2, 0, trunk});
      scene->add(SphereShape{V3(x, side * 8.7, trunk + 1.2), 1.4 + u(rng) * 1.2});
    }
    for (double x = 0; x < kLength; x += 5 + u(rng) * 10) {  // parked cars
      const double len = 4 + u(rng) * 1.2, width = 1.7 + u(rng) * 0.3, h = 1.4 + u(rng) * 0.4;
      const double y = side * 4.6;
      scene->add(BoxShape{V3(x, y - width / 2, 0.2), V3(x + len, y + width / 2, h)});
    }
  }
  for (int i = 0; i < 4; ++i) {  // cars in the opposite lane
    const double x = 10 + u(rng) * (kLength - 20);
    scene->add(BoxShape{V3(x, 0.8, 0.2), V3(x + 4.5, 2.6, 1.6)});
  }
  SimScene out{"outdoor", std::move(scene), {}};
  for (double x = 2; x <= kLength - 2; x += 2.0) out.waypoints.emplace_back(x, -1.5, 1.8);
  return out;
}

SimScene makeStructuredScene(unsigned seed) {
  std::mt19937_64 rng(seed);
  std::uniform_real_distribution<double> u(0.0, 1.0);
  constexpr double kLength = kRoomLength, kWidth = kRoomWidth, kHeight = kRoomHeight;
  auto scene = benchmarkRoom();
  addWallX(*scene, 0, kLength, 0, kHeight);
  addWallX(*scene, 0, kLength, kWidth, kHeight);
  addWallY(*scene, 0, kWidth, 0, kHeight);
  addWallY(*scene, 0, kWidth, kLength, kHeight);
  // Inner walls with doorways: x = 4 splits the floor; y = 3.5 splits the right half.
  const double door1 = 1.0 + u(rng) * 1.5, door2 = 4.5 + u(rng) * 1.0;
  addWallY(*scene, 0, door1, 4.0, kHeight);
  addWallY(*scene, door1 + 1.0, door2, 4.0, kHeight);
  addWallY(*scene, door2 + 1.0, kWidth, 4.0, kHeight);
  const double door3 = 5.5 + u(rng) * 2.0;
  addWallX(*scene, 4.0, door3, 3.5, kHeight);
  addWallX(*scene, door3 + 1.0, kLength, 3.5, kHeight);
  // A free-standing L-shaped wall in the left room.
  addWallX(*scene, 1.0, 2.8, 5.2, 1.4);
  addWallY(*scene, 5.2, 6.2, 2.8, 1.4);
  // Tables, cabinets and pillars.
  for (int i = 0; i < 6; ++i) {
    const double w = 0.5 + u(rng) * 0.8, d = 0.4 + u(rng) * 0.6, h = 0.5 + u(rng) * 1.0;
    const double x = 0.4 + u(rng) * (kLength - 0.8 - w), y = 0.4 + u(rng) * (kWidth - 0.8 - d);
    scene->add(BoxShape{V3(x, y, 0), V3(x + w, y + d, h)});
  }
  scene->add(CylinderShape{Eigen::Vector2d(7.0, 1.8), 0.2, 0, kHeight});
  scene->add(CylinderShape{Eigen::Vector2d(1.8, 2.0), 0.15, 0, kHeight});
  SimScene out{"structured", std::move(scene), {}, true};
  out.waypoints = {V3(2.0, 1.5, 0.6), V3(2.0, 4.5, 0.6), V3(7.0, 5.3, 0.6), V3(7.5, 1.2, 0.6)};
  return out;
}

SimScene makeUnstructuredScene(unsigned seed) {
  std::mt19937_64 rng(seed);
  std::uniform_real_distribution<double> u(0.0, 1.0);
  constexpr double kLength = kRoomLength, kWidth = kRoomWidth;
  auto scene = benchmarkRoom();
  const std::vector<V3> stations = {V3(2.5, 1.8, 0.6), V3(2.5, 5.2, 0.6), V3(7.5, 5.2, 0.6),
                                    V3(7.5, 1.8, 0.6)};
  const auto clear_of_stations = [&](double x, double y, double r) {
    for (const V3& s : stations) {
      if (std::hypot(x - s.x(), y - s.y()) < r + 0.6) return false;
    }
    return true;
  };
  int placed = 0;
  while (placed < 28) {
    const double x = 0.3 + u(rng) * (kLength - 0.6), y = 0.3 + u(rng) * (kWidth - 0.6);
    const double kind = u(rng);
    if (kind < 0.35) {  // a rock: a cluster of 2-4 overlapping spheres
      if (!clear_of_stations(x, y, 0.8)) continue;
      const int parts = 2 + static_cast<int>(u(rng) * 3);
      for (int i = 0; i < parts; ++i) {
        const double r = 0.15 + u(rng) * 0.4;
        scene->add(SphereShape{
            V3(x + (u(rng) - 0.5) * 0.6, y + (u(rng) - 0.5) * 0.6, r * (0.3 + u(rng) * 0.8)), r});
      }
    } else if (kind < 0.6) {  // a trunk with an uneven crown
      if (!clear_of_stations(x, y, 0.9)) continue;
      const double trunk = 0.8 + u(rng) * 0.7;
      scene->add(CylinderShape{Eigen::Vector2d(x, y), 0.06 + u(rng) * 0.1, 0, trunk});
      for (int i = 0; i < 3; ++i) {
        scene->add(SphereShape{
            V3(x + (u(rng) - 0.5) * 0.5, y + (u(rng) - 0.5) * 0.5, trunk + u(rng) * 0.3),
            0.25 + u(rng) * 0.3});
      }
    } else if (kind < 0.85) {  // debris: a small pile of boxes of random sizes
      if (!clear_of_stations(x, y, 0.7)) continue;
      double z = 0;
      for (int i = 0; i < 1 + static_cast<int>(u(rng) * 3); ++i) {
        const double w = 0.2 + u(rng) * 0.6, d = 0.2 + u(rng) * 0.6, h = 0.1 + u(rng) * 0.4;
        const double cx = x + (u(rng) - 0.5) * 0.3, cy = y + (u(rng) - 0.5) * 0.3;
        scene->add(BoxShape{V3(cx - w / 2, cy - d / 2, z), V3(cx + w / 2, cy + d / 2, z + h)});
        z += h;
      }
    } else {  // a thin post
      if (!clear_of_stations(x, y, 0.3)) continue;
      scene->add(CylinderShape{Eigen::Vector2d(x, y), 0.03 + u(rng) * 0.05, 0, 0.5 + u(rng) * 1.5});
    }
    ++placed;
  }
  SimScene out{"unstructured", std::move(scene), stations, true};
  return out;
}

Expected<SimScene> makeScene(const std::string& name_or_file, unsigned seed) {
  if (name_or_file == "structured") return makeStructuredScene(seed);
  if (name_or_file == "unstructured") return makeUnstructuredScene(seed);
  if (name_or_file == "indoor") return makeIndoorScene(seed);
  if (name_or_file == "outdoor") return makeOutdoorScene(seed);
  if (name_or_file.starts_with("street:")) {  // street:LENGTH_M, the outdoor scene made longer
    const std::string length = name_or_file.substr(7);
    char* end = nullptr;
    const double m = std::strtod(length.c_str(), &end);
    if (length.empty() || *end != '\0' || !(m >= 20.0 && m <= 50000.0)) {
      return makeError("scene " + name_or_file + ": the street length must be 20..50000 m");
    }
    SimScene street = makeOutdoorScene(seed, m);
    street.name = name_or_file;
    return street;
  }
  return makeOctreeScene(name_or_file);
}

}  // namespace densemap
