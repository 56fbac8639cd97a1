// Prints a .dmap snapshot's version and its occupied cells (log-odds > 0) as the Foxglove test
// client writes them: one "x y z" a line (the key less 32768 on each axis), sorted as text.
// Usage: dmap_occupied FILE.dmap OUT.txt   (prints the version on stdout)
#include <algorithm>
#include <cstdio>
#include <fstream>
#include <string>
#include <vector>

#include "densemap/map/sensor_model.hpp"
#include "densemap/store/snapshot.hpp"

int main(int argc, char** argv) {
  if (argc != 3) {
    std::fprintf(stderr, "usage: dmap_occupied FILE.dmap OUT.txt\n");
    return 2;
  }
  auto loaded = densemap::loadSnapshot(argv[1], densemap::Backend::kGrid, 0.0);
  if (!loaded) {
    std::fprintf(stderr, "dmap_occupied: %s\n", loaded.error().message.c_str());
    return 1;
  }
  std::vector<std::string> cells;
  loaded->map->forEachKnown([&](const densemap::VoxelKey& k, float log_odds) {
    if (!densemap::SensorModel::isOccupied(log_odds)) return;
    constexpr int kOffset = densemap::VoxelGrid::kMaxKey;
    cells.push_back(std::to_string(int{k.x} - kOffset) + " " + std::to_string(int{k.y} - kOffset) +
                    " " + std::to_string(int{k.z} - kOffset));
  });
  std::sort(cells.begin(), cells.end());
  std::ofstream out(argv[2]);
  for (const std::string& c : cells) out << c << '\n';
  std::printf("%llu\n", static_cast<unsigned long long>(loaded->version));
  return out ? 0 : 1;
}
