// A query request as the server holds it once DDS has decoded it (any floats, any
// lengths, any counts): point batches, boxes and rays against a small map, through the same
// functions the server answers with (core/pipeline map_queries). Nothing may crash, hang or
// allocate beyond the request's own size and the configured limits.
#include <algorithm>
#include <cstring>
#include <vector>

#include "densemap/map/grid_map.hpp"
#include "densemap/query/map_queries.hpp"
#include "fuzz_input.hpp"

namespace {

const densemap::MapView& smallMap() {
  static const auto view = [] {
    densemap::GridMap map(0.1, densemap::SensorModel{});
    for (float x = -1.0F; x < 1.0F; x += 0.1F) {
      for (float y = -1.0F; y < 1.0F; y += 0.1F) {
        map.setLogOdds(*map.grid().pointToKey({x, y, 0.05F}), (x + y > 0.5F) ? 2.0F : -1.0F);
      }
    }
    return densemap::MapView::fromMap(map, 3);
  }();
  return *view;
}

densemap::Point3f takePoint(densemap::fuzz::Reader& in) {
  const float x = in.take<float>(), y = in.take<float>(), z = in.take<float>();
  return {x, y, z};
}

}  // namespace

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  densemap::fuzz::Reader in(data, size);
  const densemap::MapView& view = smallMap();
  switch (in.take<std::uint8_t>() % 3) {
    case 0: {  // a point batch: the rest of the input as floats (any length)
      std::vector<float> xyz(in.restSize() / sizeof(float));
      std::memcpy(xyz.data(), in.rest(), xyz.size() * sizeof(float));
      (void)densemap::queryPoints(view, xyz, 100000);
      break;
    }
    case 1: {  // a box, the server's cell limit and a centres count from the wire
      const densemap::Point3f lo = takePoint(in), hi = takePoint(in);
      const auto centers = in.take<std::uint32_t>();
      (void)densemap::queryBox(view, lo, hi, 2'000'000,
                               std::min<std::uint32_t>(centers, 1'000'000));
      break;
    }
    default: {  // a ray
      const densemap::Point3f origin = takePoint(in), direction = takePoint(in);
      (void)densemap::castRay(view, origin, direction, in.take<float>());
      break;
    }
  }
  return 0;
}
