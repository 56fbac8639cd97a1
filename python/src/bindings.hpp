#pragma once

// What the binding rooms share: errors as Python exceptions, NumPy arrays in and out.
#include <pybind11/numpy.h>
#include <pybind11/pybind11.h>

#include <stdexcept>
#include <string>

#include "densemap/geometry/error.hpp"
#include "densemap/geometry/point_cloud.hpp"
#include "densemap/planner/planner_types.hpp"
#include "point_array.hpp"

namespace densemap::python {

namespace py = pybind11;

/// densemap.Error: a refusal or failure of densemap itself (bad option, refused scan, file
/// error, server timeout), with the message the CLI prints for the same cause.
struct DensemapError : std::runtime_error {
  using std::runtime_error::runtime_error;
};

/// The value, or densemap.Error with the error's message.
template <class T>
T valueOrRaise(Expected<T> e) {
  if (!e) throw DensemapError(e.error().message);
  if constexpr (!std::is_void_v<T>) return std::move(*e);
}

/// Runs `f` (returning an Expected) with the GIL released: the value, or densemap.Error.
template <class F>
auto released(F&& f) {
  py::gil_scoped_release release;
  return valueOrRaise(f());
}

/// A box's cell counts as the dict both Mapper.query_box and Client.query_box return.
template <class Counts>
py::dict countsDict(const Counts& c) {
  py::dict d;
  d["occupied"] = c.occupied;
  d["free"] = c.free;
  d["unknown"] = c.unknown;
  return d;
}

/// An (N, 3) float array (a NumPy array as it is, anything else through np.asarray as float64)
/// as points: ValueError for a wrong shape, a non-contiguous array or too many points,
/// TypeError for a dtype that is not float32 / float64.
[[nodiscard]] PointCloud pointsFrom(const py::handle& object, std::size_t max_points,
                                    const std::string& what, bool reject_non_finite);
/// Three finite numbers (any sequence or array).
[[nodiscard]] Point3f pointFrom(const py::handle& object, const std::string& what);
/// A 4x4 transform (any sequence or array), row-major.
[[nodiscard]] std::array<double, 16> matrixFrom(const py::handle& object, const std::string& what);
/// A 4x4 transform (matrixFrom), finite, with last row (0, 0, 0, 1); ValueError otherwise.
[[nodiscard]] Eigen::Isometry3d poseFrom(const py::handle& T, const std::string& what);
/// `points` as an (N, 3) float32 array (a copy Python owns).
[[nodiscard]] py::array_t<float> pointsArray(const PointCloud& points);

void bindMapper(py::module_& m);
void bindClient(py::module_& m);
void bindReaders(py::module_& m);

/// A distance answer as arrays: (distances float32 (N,), gradients (N, 3), nearest (N, 3)).
inline py::tuple distanceArrays(const DistanceQueryResult& r) {
  const auto n = static_cast<py::ssize_t>(r.distances.size());
  py::array_t<float> d(n);
  py::array_t<float> g({n, py::ssize_t{3}});
  py::array_t<float> c({n, py::ssize_t{3}});
  std::copy(r.distances.begin(), r.distances.end(), d.mutable_data());
  std::copy(r.gradients.begin(), r.gradients.end(), g.mutable_data());
  std::copy(r.nearest.begin(), r.nearest.end(), c.mutable_data());
  return py::make_tuple(d, g, c);
}

/// A swept-volume answer as a dict: state ('free', 'unknown', 'occupied'), the first occupied
/// and unknown cells ({'center', 'arc_length', index_name} or None), the path's length.
inline py::dict sweptDict(const SweptVolumeResult& r, const char* index_name) {
  const auto conflict = [&](const std::optional<SweptConflict>& c) -> py::object {
    if (!c) return py::none();
    py::dict d;
    d["center"] = py::make_tuple(c->center.x(), c->center.y(), c->center.z());
    d["arc_length"] = c->arc_length;
    d[index_name] = c->index;
    return d;
  };
  py::dict d;
  d["state"] = r.state == CellState::kOccupied ? "occupied"
               : r.state == CellState::kFree   ? "free"
                                               : "unknown";
  d["occupied"] = conflict(r.occupied);
  d["unknown"] = conflict(r.unknown);
  d["length"] = r.length_m;
  return d;
}

/// Oriented boxes from centers and half_extents (N, 3) and rotations (N, 4: x y z w).
std::vector<OrientedBox> boxesFrom(const py::handle& centers, const py::handle& half_extents,
                                   const py::handle& rotations);

/// A dense distance box as (distances float32 (nz, ny, nx), the centre of cell [0, 0, 0]).
inline py::tuple distanceGrid(const std::array<std::uint32_t, 3>& size,
                              const std::vector<float>& distances, const Point3f& min_center) {
  py::array_t<float> a({static_cast<py::ssize_t>(size[2]), static_cast<py::ssize_t>(size[1]),
                        static_cast<py::ssize_t>(size[0])});
  std::copy(distances.begin(), distances.end(), a.mutable_data());
  return py::make_tuple(a, py::make_tuple(min_center.x(), min_center.y(), min_center.z()));
}

}  // namespace densemap::python
