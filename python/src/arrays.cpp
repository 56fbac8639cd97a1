#include <cstring>

#include "bindings.hpp"

namespace densemap::python {
namespace {

ArrayView viewOf(const py::array& a) {
  ArrayView v;
  v.data = a.data();
  for (py::ssize_t d = 0; d < a.ndim(); ++d) {
    v.shape.push_back(a.shape(d));
    v.strides.push_back(a.strides(d));
  }
  v.kind = a.dtype().kind();
  v.itemsize = a.itemsize();
  return v;
}

/// A NumPy array as given, or anything else converted to float64 (a list of numbers).
py::array asArray(const py::handle& object, const std::string& what) {
  if (py::isinstance<py::array>(object)) return py::reinterpret_borrow<py::array>(object);
  auto converted = py::array_t<double, py::array::forcecast>::ensure(object);
  if (!converted) throw py::type_error(what + " must be an array of numbers");
  return converted;
}

[[noreturn]] void raiseArrayError(const ArrayView& v, const Error& e) {
  if (v.kind != 'f' || (v.itemsize != 4 && v.itemsize != 8)) throw py::type_error(e.message);
  throw py::value_error(e.message);
}

}  // namespace

PointCloud pointsFrom(const py::handle& object, std::size_t max_points, const std::string& what,
                      bool reject_non_finite) {
  const py::array a = asArray(object, what);
  const ArrayView v = viewOf(a);
  if (auto n = checkPoints(v, max_points, what); !n) raiseArrayError(v, n.error());
  PointCloud points;
  if (auto ok = readPoints(v, points, reject_non_finite, what); !ok) {
    throw py::value_error(ok.error().message);
  }
  return points;
}

Point3f pointFrom(const py::handle& object, const std::string& what) {
  const py::array a = asArray(object, what);
  const ArrayView v = viewOf(a);
  auto p = readPoint(v, what);
  if (!p) raiseArrayError(v, p.error());
  return *p;
}

std::array<double, 16> matrixFrom(const py::handle& object, const std::string& what) {
  const py::array a = asArray(object, what);
  const ArrayView v = viewOf(a);
  auto m = readMatrix4(v, what);
  if (!m) raiseArrayError(v, m.error());
  return *m;
}

Eigen::Isometry3d poseFrom(const py::handle& T, const std::string& what) {
  const auto m = matrixFrom(T, what);
  Eigen::Matrix4d matrix;
  for (int r = 0; r < 4; ++r) {
    for (int c = 0; c < 4; ++c) matrix(r, c) = m[r * 4 + c];
  }
  const Eigen::Vector4d last_row(0, 0, 0, 1);
  if (!matrix.allFinite() || !matrix.row(3).transpose().isApprox(last_row, 1e-9)) {
    throw py::value_error(what + " must be a finite 4x4 transform with last row (0, 0, 0, 1)");
  }
  Eigen::Isometry3d pose;
  pose.matrix() = matrix;
  return pose;
}

py::array_t<float> pointsArray(const PointCloud& points) {
  py::array_t<float> out({static_cast<py::ssize_t>(points.size()), py::ssize_t{3}});
  if (!points.empty()) std::memcpy(out.mutable_data(), points.data(), points.size() * 12);
  return out;
}

}  // namespace densemap::python
