// Insert a scan of a wall, query two points, save an OctoMap .bt (octovis opens it).
#include <cstdio>
#include <densemap/mapper/mapper.hpp>
#include <vector>

int main(int argc, char** argv) {
  auto map = densemap::Mapper::create({.resolution_m = 0.1, .max_range_m = 30.0});
  if (!map) return std::fprintf(stderr, "%s\n", map.error().message.c_str()), 1;
  std::vector<densemap::Point3f> scan;  // a wall 4 m ahead, 2 x 2 m
  for (float y = -1; y <= 1; y += 0.05F) {
    for (float z = -1; z <= 1; z += 0.05F) scan.emplace_back(4.0F, y, z);
  }
  auto inserted = map->insertPointCloud(scan, densemap::Point3f::Zero());
  if (!inserted) return std::fprintf(stderr, "%s\n", inserted.error().message.c_str()), 1;
  const char* names[] = {"unknown", "free", "occupied"};
  for (const densemap::Point3f p : {densemap::Point3f(4.0F, 0, 0), densemap::Point3f(2, 0, 0)}) {
    const densemap::CellInfo cell = map->query(p);
    std::printf("(%.1f %.1f %.1f): %s, p = %.3f\n", p.x(), p.y(), p.z(),
                names[static_cast<int>(cell.state)], cell.probability());
  }
  auto saved = map->save(argc > 1 ? argv[1] : "simple_map.bt");
  if (!saved) return std::fprintf(stderr, "%s\n", saved.error().message.c_str()), 1;
  std::printf("wrote %zu bytes, %zu known cells\n", *saved, map->knownCells());
}
