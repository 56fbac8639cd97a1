#pragma once

// What the binding rooms share: errors as Python exceptions, NumPy arrays in and out.
#include <pybind11/numpy.h>
#include <pybind11/pybind11.h>

#include <stdexcept>
#include <string>

#include "densemap/geometry/error.hpp"
#include "densemap/geometry/point_cloud.hpp"
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
/// `points` as an (N, 3) float32 array (a copy Python owns).
[[nodiscard]] py::array_t<float> pointsArray(const PointCloud& points);

void bindMapper(py::module_& m);
void bindClient(py::module_& m);
void bindReaders(py::module_& m);

}  // namespace densemap::python
