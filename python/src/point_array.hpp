#pragma once

// NumPy arrays as the Python module receives them, checked and read without Python: a plain
// description of the buffer (pybind11 fills it in), so the checks are tested and fuzzed alone.
#include <cstddef>
#include <cstdint>
#include <span>
#include <string>
#include <vector>

#include "densemap/geometry/error.hpp"
#include "densemap/geometry/point_cloud.hpp"

namespace densemap::python {

/// A buffer as NumPy describes it.
struct ArrayView {
  const void* data = nullptr;
  std::vector<std::int64_t> shape;
  std::vector<std::int64_t> strides;  // bytes
  char kind = 'f';                    // NumPy dtype kind: 'f' float, 'i' int, ...
  std::int64_t itemsize = 4;
};

/// An (N, 3) array of points: float32 or float64, C- or F-contiguous, N in [1, max_points].
/// `what` names the argument in errors ("points must be an (N, 3) array, got shape (4,)").
/// Returns N.
[[nodiscard]] Expected<std::size_t> checkPoints(const ArrayView& a, std::size_t max_points,
                                                const std::string& what);
/// Reads a checked points array into `out` (x y z per point, float; float64 rounded once).
/// With `reject_non_finite`, an error names the first NaN / Inf point.
[[nodiscard]] Expected<void> readPoints(const ArrayView& a, PointCloud& out, bool reject_non_finite,
                                        const std::string& what);
/// Whether the checked array is float32 and C-contiguous: its buffer is x y z per point as it
/// stands (no copy needed).
[[nodiscard]] bool isPackedFloat32(const ArrayView& a);
/// One point: a float array of 3 values (shape (3,), or (1, 3)), finite.
[[nodiscard]] Expected<Point3f> readPoint(const ArrayView& a, const std::string& what);
/// A 4x4 rigid transform (float64 or float32, any layout NumPy gives), row-major out.
[[nodiscard]] Expected<std::array<double, 16>> readMatrix4(const ArrayView& a,
                                                           const std::string& what);

}  // namespace densemap::python
