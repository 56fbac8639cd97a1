// wall_scan: the smallest densemap client. It sends one scan of a wall 4 m in front of the
// sensor to a running densemap-server, waits until the server has integrated it, then asks
// what the map knows: a point on the wall, a point in front of it, a ray, and the box around
// the wall. Loopback only, like the server's default.
//   wall_scan [DOMAIN_ID]
#include <chrono>
#include <cstdio>
#include <cstdlib>
#include <string>
#include <thread>

#include "densemap/client/client.hpp"

namespace {

const char* stateName(densemap::CellState s) {
  switch (s) {
    case densemap::CellState::kOccupied:
      return "occupied";
    case densemap::CellState::kFree:
      return "free";
    default:
      return "unknown";
  }
}

int fail(const std::string& what) {
  std::fprintf(stderr, "wall_scan: %s\n", what.c_str());
  return 1;
}

}  // namespace

int main(int argc, char** argv) {
  densemap::ClientOptions options;
  options.domain_id = argc > 1 ? static_cast<std::uint32_t>(std::atoi(argv[1])) : 0;
  options.network_interface = "lo";
  auto client = densemap::Client::create(options);
  if (!client) return fail(client.error().message);
  if (auto ok = (*client)->waitForServer(); !ok) return fail(ok.error().message);
  auto before = (*client)->status();
  const std::uint64_t integrated_before = before ? before->integrated : 0;

  // A 2 m x 1.6 m wall at x = 4 m, one point every 2 cm, seen from the origin.
  densemap::RawScan scan;
  scan.sensor_id = "wall_scan";
  scan.seq = 1;
  for (int iy = -50; iy <= 50; ++iy) {
    for (int iz = -40; iz <= 40; ++iz) {
      scan.xyz.insert(scan.xyz.end(), {4.0F, 0.02F * iy, 0.02F * iz});
    }
  }
  if (auto ok = (*client)->publishScan(scan); !ok) return fail(ok.error().message);

  // The status is published once a second: wait until it counts the scan.
  for (int i = 0; i < 100; ++i) {
    auto s = (*client)->status();
    if (s && s->integrated > integrated_before) break;
    std::this_thread::sleep_for(std::chrono::milliseconds(100));
  }
  auto points = (*client)->queryPoints({{4.0F, 0.0F, 0.0F}, {2.0F, 0.0F, 0.0F}, {9, 9, 9}});
  if (!points) return fail(points.error().message);
  std::printf("map version %llu\n", static_cast<unsigned long long>(points->map_version));
  std::printf("(4, 0, 0) on the wall: %s\n", stateName(points->states[0]));
  std::printf("(2, 0, 0) in front of it: %s\n", stateName(points->states[1]));
  std::printf("(9, 9, 9) never seen: %s\n", stateName(points->states[2]));
  auto ray = (*client)->castRay({0, 0, 0}, {1, 0, 0}, 10.0F);
  if (!ray) return fail(ray.error().message);
  std::printf("ray along +x: %s at %.2f m\n", ray->ray.hit ? "hit" : "no hit", ray->ray.distance);
  auto box = (*client)->queryBox({3.5F, -1.0F, -0.8F}, {4.5F, 1.0F, 0.8F});
  if (!box) return fail(box.error().message);
  std::printf("box around the wall: %llu occupied, %llu free, %llu unknown cells\n",
              static_cast<unsigned long long>(box->occupied),
              static_cast<unsigned long long>(box->free),
              static_cast<unsigned long long>(box->unknown));
  return points->states[0] == densemap::CellState::kOccupied ? 0 : 1;
}
