// Planner requests as the server and the Mapper take them (any floats, any lengths): distance
// batches (either unknown policy, interpolated or not), paths with a radius, oriented boxes (from
// the wire's flat floats) and distance boxes, against a small map with its distance field, through the functions that
// answer them (core/planner). Nothing may crash, hang or allocate beyond the request's own size
// and the limits.
#include <cstring>
#include <vector>

#include "densemap/map/grid_map.hpp"
#include "densemap/planner/distance_field.hpp"
#include "densemap/planner/distance_query.hpp"
#include "densemap/planner/swept_volume.hpp"
#include "fuzz_input.hpp"

namespace {

struct SmallMap {
  std::shared_ptr<const densemap::MapView> view;
  std::optional<densemap::DistanceField> field;
};

const SmallMap& smallMap() {
  static const SmallMap map = [] {
    densemap::GridMap grid(0.1, densemap::SensorModel{});
    for (float x = -1.0F; x < 1.0F; x += 0.1F) {
      for (float y = -1.0F; y < 1.0F; y += 0.1F) {
        grid.setLogOdds(*grid.grid().pointToKey({x, y, 0.05F}), (x + y > 0.5F) ? 2.0F : -1.0F);
      }
    }
    SmallMap m;
    m.view = densemap::MapView::fromMap(grid, 3);
    m.field = *densemap::DistanceField::create(0.1, {.max_distance_m = 0.5});
    m.field->rebuild(*m.view);
    return m;
  }();
  return map;
}

densemap::Point3f takePoint(densemap::fuzz::Reader& in) {
  const float x = in.take<float>(), y = in.take<float>(), z = in.take<float>();
  return {x, y, z};
}

std::vector<float> restAsFloats(densemap::fuzz::Reader& in) {
  std::vector<float> xyz(in.restSize() / sizeof(float));
  std::memcpy(xyz.data(), in.rest(), xyz.size() * sizeof(float));
  return xyz;
}

}  // namespace

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  densemap::fuzz::Reader in(data, size);
  const SmallMap& map = smallMap();
  const auto op = in.take<std::uint8_t>();
  // Small limits, so that a large request is refused before it costs time.
  densemap::SweptVolumeLimits limits;
  limits.max_vertices = 2000;
  limits.max_boxes = 200;
  limits.max_cells = 2'000'000;
  switch (op % 4) {
    case 0: {  // distances: the rest as x y z floats
      densemap::DistanceQueryOptions o;
      o.unknown_as_occupied = (op & 0x10) != 0;
      o.interpolate = (op & 0x20) != 0;
      o.nearest = (op & 0x40) != 0;
      const std::vector<float> xyz = restAsFloats(in);
      (void)densemap::queryDistances(*map.field, *map.view, xyz, o, 20000,
                                     densemap::serialRunner());
      break;
    }
    case 1: {  // a path: a radius, then vertices
      const float radius = in.take<float>();
      const std::vector<float> xyz = restAsFloats(in);
      (void)densemap::checkPath(*map.view, xyz, radius, limits);
      break;
    }
    case 2: {  // oriented boxes as the wire carries them (10 floats each), as the server reads them
      const std::vector<float> floats = restAsFloats(in);
      auto boxes = densemap::boxesFromFloats(floats, limits.max_boxes);
      if (boxes) (void)densemap::checkBoxes(*map.view, *boxes, limits);
      break;
    }
    default: {  // a distance box
      const densemap::Point3f lo = takePoint(in), hi = takePoint(in);
      (void)densemap::exportDistanceBox(*map.field, *map.view, lo, hi, (op & 0x10) != 0, 200'000);
      break;
    }
  }
  return 0;
}
