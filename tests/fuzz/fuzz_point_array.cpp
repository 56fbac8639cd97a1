// NumPy arrays as the Python module receives them: any shape, strides, dtype kind and item
// size over a buffer that holds what the shape and strides address (NumPy's guarantee), through
// the module's checks and readers (python/src/point_array.hpp). Nothing may crash, read outside
// the buffer, or allocate beyond the points the limit allows.
#include <algorithm>
#include <cstdint>
#include <vector>

#include "fuzz_input.hpp"
#include "point_array.hpp"

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  densemap::fuzz::Reader in(data, size);
  densemap::python::ArrayView a;
  const int ndim = in.take<std::uint8_t>() % 4;
  static const char kinds[] = {'f', 'i', 'u', 'b', 'c', 'O'};
  a.kind = kinds[in.take<std::uint8_t>() % sizeof(kinds)];
  a.itemsize = std::int64_t{1} << (in.take<std::uint8_t>() % 5);  // 1 .. 16
  // Shapes up to 64 per axis (the claimed count of a larger array is checked against the
  // limit before anything is read: one axis may claim up to 2^40).
  std::int64_t span_bytes = a.itemsize;
  for (int d = 0; d < ndim; ++d) {
    const bool huge = in.take<std::uint8_t>() == 0xff;
    a.shape.push_back(huge ? std::int64_t{1} << 40 : in.take<std::uint8_t>() % 65);
  }
  for (int d = 0; d < ndim; ++d) {
    // Non-negative strides, as NumPy's contiguous or sliced arrays have them.
    a.strides.push_back(static_cast<std::int64_t>(in.take<std::uint8_t>() % 64));
  }
  bool fits = true;
  for (int d = 0; d < ndim; ++d) {
    if (a.shape[d] == 0) continue;
    if (a.shape[d] > 64) fits = false;
    span_bytes += (std::min<std::int64_t>(a.shape[d], 64) - 1) * a.strides[d];
  }
  std::vector<std::uint8_t> buffer(static_cast<std::size_t>(span_bytes));
  const std::size_t rest = std::min(buffer.size(), in.restSize());
  for (std::size_t i = 0; i < rest; ++i) buffer[i] = in.take<std::uint8_t>();
  a.data = buffer.data();
  const std::size_t limit = 1000;
  if (auto n = densemap::python::checkPoints(a, limit, "points"); n) {
    // Checked arrays are read only when their buffer is as large as they claim.
    if (!fits) __builtin_trap();
    densemap::PointCloud points;
    (void)densemap::python::readPoints(a, points, true, "points");
    if (points.size() != *n) __builtin_trap();
  }
  if (fits) {
    (void)densemap::python::readPoint(a, "origin");
    (void)densemap::python::readMatrix4(a, "pose");
  }
  return 0;
}
