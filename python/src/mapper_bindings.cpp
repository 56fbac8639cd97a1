// densemap.Mapper and densemap.load: the in-process map (densemap/mapper/mapper.hpp).
#include <pybind11/stl.h>
#include <pybind11/stl/filesystem.h>

#include <cmath>
#include <filesystem>
#include <limits>

#include "bindings.hpp"
#include "densemap/geometry/rigid_transform.hpp"
#include "densemap/mapper/mapper.hpp"

namespace densemap::python {
namespace {

using Box = std::optional<std::pair<Point3f, Point3f>>;

/// `bounds`: None or ((min_x, min_y, min_z), (max_x, max_y, max_z)).
Box boxFrom(const py::object& bounds) {
  if (bounds.is_none()) return std::nullopt;
  const auto pair = bounds.cast<py::sequence>();
  if (pair.size() != 2) throw py::value_error("bounds must be (min, max), each 3 numbers");
  return std::pair(pointFrom(pair[0], "bounds min"), pointFrom(pair[1], "bounds max"));
}

MapperOptions optionsFrom(double resolution, double max_range, const std::string& kind,
                          const std::string& backend, const std::string& integration,
                          const std::string& update_rule, int threads, double prob_hit,
                          double prob_miss, double clamp_min, double clamp_max, double keep_radius,
                          const py::object& bounds, std::size_t max_points, bool versioned_reads,
                          bool distance_field, double max_distance, const py::object& decay_after,
                          double decay_period) {
  MapperOptions o;
  o.resolution_m = resolution;
  o.max_range_m = max_range;
  o.kind = kind;
  o.backend = backend;
  o.integration = integration;
  o.update_rule = update_rule;
  o.threads = threads;
  o.sensor = {prob_hit, prob_miss, clamp_min, clamp_max};
  o.keep_radius_m = keep_radius;
  o.bounds = boxFrom(bounds);
  o.max_points = max_points;
  o.versioned_reads = versioned_reads;
  o.distance_field = distance_field;
  o.max_distance_m = max_distance;
  if (!decay_after.is_none()) {
    o.decay = DecayOptions{.after_s = decay_after.cast<double>(), .period_s = decay_period};
  }
  return o;
}

/// (distances (N,), gradients (N, 3), nearest obstacles (N, 3)) of `points`.
py::tuple distances(const Mapper& mapper, const py::handle& points, bool unknown_as_occupied,
                    bool interpolate, bool nearest) {
  const PointCloud cloud =
      pointsFrom(points, std::numeric_limits<std::size_t>::max(), "points", false);
  const std::span<const float> xyz(cloud.empty() ? nullptr : cloud.front().data(),
                                   cloud.size() * 3);
  return distanceArrays(released([&] {
    return mapper.distance(xyz, {.unknown_as_occupied = unknown_as_occupied,
                                 .interpolate = interpolate,
                                 .nearest = nearest});
  }));
}

InsertResult insertPoints(Mapper& mapper, const py::handle& points, const py::handle& origin,
                          std::optional<double> stamp) {
  // Non-finite points are the engine's to refuse (its message, the map unchanged).
  const PointCloud cloud = pointsFrom(points, mapper.options().max_points, "points", false);
  const Point3f o = pointFrom(origin, "origin");
  py::gil_scoped_release release;
  return valueOrRaise(mapper.insertPointCloud(cloud, o, stamp));
}

/// Queries `points` once: (log-odds, states), both of length N.
std::pair<py::array_t<float>, py::array_t<std::uint8_t>> queryArrays(const Mapper& mapper,
                                                                     const py::handle& points) {
  const PointCloud cloud =
      pointsFrom(points, std::numeric_limits<std::size_t>::max(), "points", false);
  const auto n = static_cast<py::ssize_t>(cloud.size());
  py::array_t<float> log_odds(n);
  py::array_t<std::uint8_t> states(n);
  {
    const std::span<const float> xyz(cloud.front().data(), cloud.size() * 3);
    std::span<float> out(log_odds.mutable_data(), cloud.size());
    std::span<CellState> st(reinterpret_cast<CellState*>(states.mutable_data()), cloud.size());
    py::gil_scoped_release release;
    valueOrRaise(mapper.query(xyz, out, st));
  }
  return {log_odds, states};
}

py::array_t<float> probabilities(const py::array_t<float>& log_odds) {
  py::array_t<float> p(log_odds.size());
  const float* in = log_odds.data();
  float* out = p.mutable_data();
  for (py::ssize_t i = 0; i < log_odds.size(); ++i) {
    out[i] = std::isnan(in[i]) ? std::numeric_limits<float>::quiet_NaN()
                               : static_cast<float>(SensorModel::probability(in[i]));
  }
  return p;
}

CellFilter filterFrom(const std::string& which) {
  if (which == "known") return CellFilter::kKnown;
  if (which == "occupied") return CellFilter::kOccupied;
  if (which == "free") return CellFilter::kFree;
  throw py::value_error("which must be 'known', 'occupied' or 'free', got '" + which + "'");
}

/// The cells `filter` selects, in the box or the whole map: (centres (M, 3), log-odds (M,)).
std::pair<py::array_t<float>, py::array_t<float>> cellsOf(const Mapper& mapper,
                                                          const py::object& box_min,
                                                          const py::object& box_max,
                                                          CellFilter filter) {
  if (box_min.is_none() != box_max.is_none()) {
    throw py::value_error("give both box_min and box_max, or neither");
  }
  PointCloud centres;
  std::vector<float> values;
  const auto collect = [&](const Point3f& c, float v) {
    centres.push_back(c);
    values.push_back(v);
  };
  if (box_min.is_none()) {
    py::gil_scoped_release release;
    mapper.forEachCell(filter, collect);
  } else {
    const Point3f lo = pointFrom(box_min, "box_min"), hi = pointFrom(box_max, "box_max");
    py::gil_scoped_release release;
    valueOrRaise(mapper.forEachCell(lo, hi, filter, collect));
  }
  py::array_t<float> v(static_cast<py::ssize_t>(values.size()));
  std::copy(values.begin(), values.end(), v.mutable_data());
  return {pointsArray(centres), v};
}

py::tuple castRays(const Mapper& mapper, const py::handle& origins, const py::handle& directions,
                   float max_range) {
  const std::size_t limit = mapper.options().max_points;
  const PointCloud dirs = pointsFrom(directions, limit, "directions", true);
  PointCloud from;
  const py::array as_array = py::array::ensure(origins);
  if (as_array && as_array.ndim() == 1) {
    from.assign(dirs.size(), pointFrom(origins, "origins"));
  } else {
    from = pointsFrom(origins, limit, "origins", true);
    if (from.size() != dirs.size()) {
      throw py::value_error("origins and directions differ in length: " +
                            std::to_string(from.size()) + " and " + std::to_string(dirs.size()));
    }
  }
  const auto n = static_cast<py::ssize_t>(dirs.size());
  py::array_t<bool> hit(n);
  py::array_t<float> distance(n);
  PointCloud centres(dirs.size());
  {
    py::gil_scoped_release release;
    for (std::size_t i = 0; i < dirs.size(); ++i) {
      auto r = mapper.castRay(from[i], dirs[i], max_range);
      if (!r) throw DensemapError("ray " + std::to_string(i) + ": " + r.error().message);
      hit.mutable_data()[i] = r->hit;
      distance.mutable_data()[i] = r->hit ? r->distance : std::numeric_limits<float>::infinity();
      centres[i] = r->hit ? r->center : Point3f::Constant(std::numeric_limits<float>::quiet_NaN());
    }
  }
  return py::make_tuple(hit, pointsArray(centres), distance);
}

py::array_t<std::uint64_t> blocksArray(const std::vector<std::uint64_t>& blocks) {
  py::array_t<std::uint64_t> out(static_cast<py::ssize_t>(blocks.size()));
  std::copy(blocks.begin(), blocks.end(), out.mutable_data());
  return out;
}

py::dict optionsDict(const MapperOptions& o) {
  py::dict d;
  d["resolution"] = o.resolution_m;
  d["max_range"] = o.max_range_m;
  d["kind"] = o.kind;
  d["backend"] = o.backend;
  d["integration"] = o.integration;
  d["update_rule"] = o.update_rule;
  d["threads"] = o.threads;
  d["prob_hit"] = o.sensor.hit;
  d["prob_miss"] = o.sensor.miss;
  d["clamp_min"] = o.sensor.clamp_min;
  d["clamp_max"] = o.sensor.clamp_max;
  d["keep_radius"] = o.keep_radius_m;
  d["max_points"] = o.max_points;
  d["versioned_reads"] = o.versioned_reads;
  d["distance_field"] = o.distance_field;
  d["max_distance"] = o.max_distance_m;
  d["decay_after"] = o.decay ? py::cast(o.decay->after_s) : py::none();
  d["decay_period"] = o.decay ? o.decay->period_s : DecayOptions{}.period_s;
  return d;
}

}  // namespace

std::vector<OrientedBox> boxesFrom(const py::handle& centers, const py::handle& half_extents,
                                   const py::handle& rotations) {
  const std::size_t limit = std::numeric_limits<std::size_t>::max();
  const PointCloud c = pointsFrom(centers, limit, "centers", false);
  const PointCloud e = pointsFrom(half_extents, limit, "half_extents", false);
  const auto q = py::array_t<double, py::array::c_style | py::array::forcecast>::ensure(rotations);
  if (!q || q.ndim() != 2 || q.shape(1) != 4 || static_cast<std::size_t>(q.shape(0)) != c.size() ||
      e.size() != c.size()) {
    throw py::value_error(
        "centers and half_extents (N, 3) and rotations (N, 4: x y z w) must match");
  }
  std::vector<OrientedBox> boxes(c.size());
  for (std::size_t i = 0; i < c.size(); ++i) {
    const double* r = q.data(static_cast<py::ssize_t>(i), 0);
    boxes[i].center = c[i];
    boxes[i].half_extents = e[i];
    boxes[i].rotation = Eigen::Quaternionf(static_cast<float>(r[3]), static_cast<float>(r[0]),
                                           static_cast<float>(r[1]), static_cast<float>(r[2]));
  }
  return boxes;
}

void bindMapper(py::module_& m) {
  py::class_<InsertResult>(m, "InsertResult", "What one scan did to the map.")
      .def_readonly("version", &InsertResult::version, "The map version the scan published.")
      .def_property_readonly(
          "changed_blocks", [](const InsertResult& r) { return blocksArray(r.changed_blocks); },
          "Keys (uint64) of the 8^3 blocks the scan wrote; Mapper.block_box gives their boxes.")
      .def_readonly("points", &InsertResult::points, "Points integrated.")
      .def_readonly("evicted_blocks", &InsertResult::evicted_blocks,
                    "Blocks dropped after the scan by keep_radius / bounds.")
      .def_readonly("evicted_cells", &InsertResult::evicted_cells, "Known cells dropped with them.")
      .def_readonly("decay_stepped_cells", &InsertResult::decay_stepped_cells,
                    "Occupied cells that took a decay step before the scan and stayed occupied.")
      .def_readonly("decay_erased_cells", &InsertResult::decay_erased_cells,
                    "Occupied cells that decayed to unknown before the scan.")
      .def("__repr__", [](const InsertResult& r) {
        return "InsertResult(version=" + std::to_string(r.version) +
               ", points=" + std::to_string(r.points) +
               ", changed_blocks=" + std::to_string(r.changed_blocks.size()) + ")";
      });

  const MapperOptions d;
  py::class_<Mapper>(m, "Mapper", R"doc(
An occupancy map in this process: densemap's engine (the server's), exact to OctoMap for
kind="log_odds". Thread-safe: inserts run one at a time and the GIL is released while they
integrate; queries read the latest version (see versioned_reads).

Arguments (keyword only): resolution (m), max_range (m, < 0: unlimited), kind ("log_odds",
"akimap_rays", "akimap", "bgk", "bgkl"), backend ("grid", "octree"), integration ("raycast",
"culling", "superray", "superray+culling"), update_rule ("set", "per_ray"), threads (0: all
cores), prob_hit, prob_miss, clamp_min, clamp_max (the sensor model), keep_radius (m, 0: off)
and bounds (((min_x, min_y, min_z), (max_x, max_y, max_z)) or None) bound the memory,
max_points (per scan), versioned_reads (False: inserts write in place and a query waits for an
insert under way; True: queries never wait, inserts copy the blocks they change, about a fifth
more time a scan), distance_field (keep a distance field for distance() and distance_box(),
updated with each insert) and max_distance (its maximum, m: exact below, reported beyond),
decay_after (s; None: off) and decay_period (s): a map that forgets what moved, where an occupied
cell not hit for decay_after seconds takes a miss every decay_period seconds until it is unknown
(the clock is each insert's stamp, else the time of the insert). A bad option raises
densemap.Error naming it.
)doc")
      .def(py::init([](double resolution, double max_range, const std::string& kind,
                       const std::string& backend, const std::string& integration,
                       const std::string& update_rule, int threads, double prob_hit,
                       double prob_miss, double clamp_min, double clamp_max, double keep_radius,
                       const py::object& bounds, std::size_t max_points, bool versioned_reads,
                       bool distance_field, double max_distance, const py::object& decay_after,
                       double decay_period) {
             return valueOrRaise(Mapper::create(optionsFrom(
                 resolution, max_range, kind, backend, integration, update_rule, threads, prob_hit,
                 prob_miss, clamp_min, clamp_max, keep_radius, bounds, max_points, versioned_reads,
                 distance_field, max_distance, decay_after, decay_period)));
           }),
           py::kw_only(), py::arg("resolution") = d.resolution_m,
           py::arg("max_range") = d.max_range_m, py::arg("kind") = d.kind,
           py::arg("backend") = d.backend, py::arg("integration") = d.integration,
           py::arg("update_rule") = d.update_rule, py::arg("threads") = d.threads,
           py::arg("prob_hit") = d.sensor.hit, py::arg("prob_miss") = d.sensor.miss,
           py::arg("clamp_min") = d.sensor.clamp_min, py::arg("clamp_max") = d.sensor.clamp_max,
           py::arg("keep_radius") = d.keep_radius_m, py::arg("bounds") = py::none(),
           py::arg("max_points") = d.max_points, py::arg("versioned_reads") = d.versioned_reads,
           py::arg("distance_field") = d.distance_field, py::arg("max_distance") = d.max_distance_m,
           py::arg("decay_after") = py::none(), py::arg("decay_period") = DecayOptions{}.period_s)
      .def("insert_point_cloud", &insertPoints, py::arg("points"), py::arg("origin"),
           py::arg("stamp") = py::none(),
           R"doc(Integrates world-frame points ((N, 3) float32 or float64, C- or F-contiguous)
seen from origin (3 numbers), as OctoMap's insertPointCloud; stamp (s, optional) is the scan's
time for decay_after. Returns an InsertResult. Raises
densemap.Error for a NaN / Inf point or an empty or oversized scan (the map unchanged),
ValueError / TypeError for a wrong shape or dtype.)doc")
      .def(
          "insert_scan",
          [](Mapper& self, const py::handle& points, const py::handle& T_world_sensor,
             std::optional<double> stamp) {
            const PointCloud cloud =
                pointsFrom(points, self.options().max_points, "points_sensor", false);
            const Eigen::Isometry3d pose = poseFrom(T_world_sensor, "T_world_sensor");
            py::gil_scoped_release release;
            return valueOrRaise(self.insertScan(cloud, pose, stamp));
          },
          py::arg("points_sensor"), py::arg("T_world_sensor"), py::arg("stamp") = py::none(),
          R"doc(Integrates sensor-frame points with the sensor's pose (a 4x4 rigid transform,
world from sensor): points are transformed in double and rounded once, the origin is the
pose's translation.)doc")
      .def(
          "occupancy",
          [](const Mapper& self, const py::handle& points) {
            return probabilities(queryArrays(self, points).first);
          },
          py::arg("points"),
          "The occupancy probability of each point's cell (float32, NaN where unknown).")
      .def(
          "log_odds",
          [](const Mapper& self, const py::handle& points) {
            return queryArrays(self, points).first;
          },
          py::arg("points"), "Each point's cell's log-odds (float32, NaN where unknown).")
      .def(
          "states",
          [](const Mapper& self, const py::handle& points) {
            return queryArrays(self, points).second;
          },
          py::arg("points"), "Each point's cell's state (uint8: UNKNOWN 0, FREE 1, OCCUPIED 2).")
      .def(
          "query_box",
          [](const Mapper& self, const py::handle& box_min, const py::handle& box_max,
             std::size_t max_cells) {
            const Point3f lo = pointFrom(box_min, "box_min"), hi = pointFrom(box_max, "box_max");
            const BoxCounts c = released([&] { return self.queryBox(lo, hi, max_cells); });
            return countsDict(c);
          },
          py::arg("box_min"), py::arg("box_max"), py::arg("max_cells") = 50'000'000,
          "Counts the cells of the box by state: {'occupied', 'free', 'unknown'}.")
      .def("cast_rays", &castRays, py::arg("origins"), py::arg("directions"), py::arg("max_range"),
           R"doc(Casts rays (OctoMap's traversal; unknown cells are passed through) from origins
((N, 3), or one origin for all) along directions ((N, 3), any non-zero length) up to
max_range m. Returns (hit: bool (N,), centers: float32 (N, 3) of the first occupied cells, NaN
where none, distances: float32 (N,), inf where none).)doc")
      .def("distance", &distances, py::arg("points"), py::kw_only(),
           py::arg("unknown_as_occupied") = false, py::arg("interpolate") = false,
           py::arg("nearest") = true,
           R"doc(Distances from points ((N, 3)) to the nearest occupied cell centre (or unknown
cell, with unknown_as_occupied), at most max_distance (meaning none within it), from one map
version. Returns (distances float32 (N,), gradients float32 (N, 3): unit, away from the nearest
obstacle, or the trilinear interpolant's with interpolate=True, zero at an obstacle or beyond
the maximum; nearest float32 (N, 3): the nearest obstacle cell's centre, NaN where none or
nearest=False). Needs distance_field=True; raises densemap.Error for a NaN or out-of-range
point.)doc")
      .def(
          "distance_box",
          [](const Mapper& self, const py::handle& box_min, const py::handle& box_max,
             bool unknown_as_occupied, std::size_t max_cells) {
            const Point3f lo = pointFrom(box_min, "box_min"), hi = pointFrom(box_max, "box_max");
            const DistanceGrid g =
                released([&] { return self.distanceBox(lo, hi, unknown_as_occupied, max_cells); });
            return distanceGrid(g.size, g.distances, g.min_center);
          },
          py::arg("box_min"), py::arg("box_max"), py::kw_only(),
          py::arg("unknown_as_occupied") = false, py::arg("max_cells") = 16'777'216,
          R"doc(The distance field over the box's cells: (distances float32 (nz, ny, nx), the
centre of cell [0, 0, 0]). Raises densemap.Error past max_cells.)doc")
      .def(
          "check_path",
          [](const Mapper& self, const py::handle& vertices, double radius) {
            const PointCloud path =
                pointsFrom(vertices, std::numeric_limits<std::size_t>::max(), "vertices", false);
            const std::span<const float> xyz(path.empty() ? nullptr : path.front().data(),
                                             path.size() * 3);
            return sweptDict(released([&] { return self.checkPath(xyz, radius); }), "segment");
          },
          py::arg("vertices"), py::arg("radius"),
          R"doc(Whether a robot of this radius (m) can follow the polyline vertices ((N, 3)):
every cell within the radius of the path counts. Returns {'state': 'free' | 'unknown' |
'occupied', 'occupied': the first occupied cell along the path ({'center', 'arc_length',
'segment'}) or None, 'unknown': the first unknown cell before it or None, 'length'}.)doc")
      .def(
          "check_boxes",
          [](const Mapper& self, const py::handle& centers, const py::handle& half_extents,
             const py::handle& rotations) {
            const std::vector<OrientedBox> boxes = boxesFrom(centers, half_extents, rotations);
            return sweptDict(released([&] { return self.checkBoxes(boxes); }), "box");
          },
          py::arg("centers"), py::arg("half_extents"), py::arg("rotations"),
          R"doc(The same for oriented boxes (a footprint along a trajectory): centers and
half_extents (N, 3), rotations (N, 4) as quaternions x y z w (world from box). The conflicts
name their 'box'.)doc")
      .def(
          "occupied_cells",
          [](const Mapper& self, const py::object& box_min, const py::object& box_max) {
            return cellsOf(self, box_min, box_max, CellFilter::kOccupied).first;
          },
          py::arg("box_min") = py::none(), py::arg("box_max") = py::none(),
          "Centres (float32 (M, 3)) of the occupied cells in the box, or the whole map.")
      .def(
          "cells",
          [](const Mapper& self, const py::object& box_min, const py::object& box_max,
             const std::string& which) {
            auto [centres, log_odds] = cellsOf(self, box_min, box_max, filterFrom(which));
            return py::make_tuple(centres, log_odds);
          },
          py::arg("box_min") = py::none(), py::arg("box_max") = py::none(),
          py::arg("which") = "known",
          "(centres float32 (M, 3), log_odds float32 (M,)) of the cells `which` selects "
          "('known', 'occupied', 'free') in the box, or the whole map.")
      .def(
          "clear",
          [](Mapper& self) {
            py::gil_scoped_release release;
            self.clear();
          },
          "Forgets every cell (a new, empty version).")
      .def(
          "clear_box",
          [](Mapper& self, const py::handle& box_min, const py::handle& box_max) {
            const Point3f lo = pointFrom(box_min, "box_min"), hi = pointFrom(box_max, "box_max");
            py::gil_scoped_release release;
            return valueOrRaise(self.clearBox(lo, hi));
          },
          py::arg("box_min"), py::arg("box_max"),
          "Forgets the cells of the box; returns how many known cells it dropped.")
      .def(
          "save",
          [](const Mapper& self, const std::filesystem::path& path) {
            py::gil_scoped_release release;
            return valueOrRaise(self.save(path.string()));
          },
          py::arg("path"),
          "Writes .dmap (densemap), .bt (OctoMap binary) or .ot (OctoMap log-odds) "
          "atomically; returns the bytes written.")
      .def(
          "block_box",
          [](const Mapper& self, std::uint64_t key) {
            const auto [lo, hi] = self.blockBox(key);
            return py::make_tuple(py::make_tuple(lo.x(), lo.y(), lo.z()),
                                  py::make_tuple(hi.x(), hi.y(), hi.z()));
          },
          py::arg("key"), "The box ((min), (max)) of a block in InsertResult.changed_blocks.")
      .def_property_readonly("version", &Mapper::version,
                             "The latest map version: 0 when new, one more per change.")
      .def_property_readonly("resolution", &Mapper::resolution, "Voxel edge, m.")
      .def_property_readonly("known_cells", &Mapper::knownCells, "Cells known (free or occupied).")
      .def_property_readonly("memory_bytes", &Mapper::memoryBytes, "Bytes the map holds.")
      .def_property_readonly(
          "options", [](const Mapper& self) { return optionsDict(self.options()); },
          "The options the map was made with (a dict, the constructor's names).")
      .def("__repr__", [](const Mapper& self) {
        return "densemap.Mapper(kind='" + self.options().kind +
               "', resolution=" + py::str(py::float_(self.resolution())).cast<std::string>() +
               ", known_cells=" + std::to_string(self.knownCells()) +
               ", version=" + std::to_string(self.version()) + ")";
      });

  m.def(
      "load",
      [](const std::filesystem::path& path, double max_range, const std::string& backend,
         const std::string& integration, const std::string& update_rule, int threads,
         double keep_radius, const py::object& bounds, std::size_t max_points, bool versioned_reads,
         bool distance_field, double max_distance, const py::object& decay_after,
         double decay_period) {
        const MapperOptions d;
        MapperOptions o =
            optionsFrom(d.resolution_m, max_range, d.kind, backend, integration, update_rule,
                        threads, d.sensor.hit, d.sensor.miss, d.sensor.clamp_min,
                        d.sensor.clamp_max, keep_radius, bounds, max_points, versioned_reads,
                        distance_field, max_distance, decay_after, decay_period);
        py::gil_scoped_release release;
        return valueOrRaise(Mapper::load(path.string(), o));
      },
      py::arg("path"), py::kw_only(), py::arg("max_range") = d.max_range_m,
      py::arg("backend") = d.backend, py::arg("integration") = d.integration,
      py::arg("update_rule") = d.update_rule, py::arg("threads") = d.threads,
      py::arg("keep_radius") = d.keep_radius_m, py::arg("bounds") = py::none(),
      py::arg("max_points") = d.max_points, py::arg("versioned_reads") = d.versioned_reads,
      py::arg("distance_field") = d.distance_field, py::arg("max_distance") = d.max_distance_m,
      py::arg("decay_after") = py::none(), py::arg("decay_period") = DecayOptions{}.period_s,
      R"doc(A Mapper read from a .dmap (densemap: version, sensor model, a dense map's
evidence) or .bt / .ot (OctoMap) file; the file decides the resolution, sensor model and a
dense kind, the arguments the rest. Corrupt, truncated and non-finite files raise
densemap.Error naming the file and the reason.)doc");
}

}  // namespace densemap::python
