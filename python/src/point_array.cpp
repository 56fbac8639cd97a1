#include "point_array.hpp"

#include <array>
#include <cmath>
#include <cstring>

namespace densemap::python {
namespace {

std::string shapeText(const ArrayView& a) {
  std::string s = "(";
  for (std::size_t i = 0; i < a.shape.size(); ++i) {
    s += std::to_string(a.shape[i]);
    if (a.shape.size() == 1 || i + 1 < a.shape.size()) s += i + 1 < a.shape.size() ? ", " : ",";
  }
  return s + ")";
}

bool isFloat(const ArrayView& a) { return a.kind == 'f' && (a.itemsize == 4 || a.itemsize == 8); }

Expected<void> checkFloat(const ArrayView& a, const std::string& what) {
  if (!isFloat(a)) {
    return makeError(what + " must be float32 or float64, got dtype kind '" +
                     std::string(1, a.kind) + "' of " + std::to_string(a.itemsize) + " bytes");
  }
  if (a.data == nullptr && !a.shape.empty()) return makeError(what + " has no data");
  if (a.shape.size() != a.strides.size()) return makeError(what + ": strides do not match shape");
  return {};
}

/// Element (i, j) of a 2-D float array, as double.
double at(const ArrayView& a, std::int64_t i, std::int64_t j) {
  const auto* base = static_cast<const unsigned char*>(a.data);
  const std::int64_t offset = i * a.strides[0] + j * a.strides[1];
  if (a.itemsize == 4) {
    float v;
    std::memcpy(&v, base + offset, 4);
    return v;
  }
  double v;
  std::memcpy(&v, base + offset, 8);
  return v;
}

}  // namespace

Expected<std::size_t> checkPoints(const ArrayView& a, std::size_t max_points,
                                  const std::string& what) {
  if (a.shape.size() != 2 || a.shape[1] != 3) {
    return makeError(what + " must be an (N, 3) array, got shape " + shapeText(a));
  }
  if (auto ok = checkFloat(a, what); !ok) return std::unexpected(ok.error());
  const std::int64_t n = a.shape[0];
  if (n <= 0) return makeError(what + " holds no points");
  if (static_cast<std::uint64_t>(n) > max_points) {
    return makeError(what + ": " + std::to_string(n) + " points exceed the limit of " +
                     std::to_string(max_points));
  }
  const std::int64_t item = a.itemsize;
  // A dimension of length 1 may have any stride (NumPy leaves it so).
  const bool c_order = a.strides[1] == item && (n == 1 || a.strides[0] == 3 * item);
  const bool f_order = (n == 1 || a.strides[0] == item) && a.strides[1] == n * item;
  if (!c_order && !f_order) {
    return makeError(what +
                     " must be C- or F-contiguous (np.ascontiguousarray makes a copy "
                     "that is)");
  }
  return static_cast<std::size_t>(n);
}

bool isPackedFloat32(const ArrayView& a) {
  return a.itemsize == 4 && a.shape.size() == 2 && a.strides[1] == 4 &&
         (a.shape[0] == 1 || a.strides[0] == 12);
}

Expected<void> readPoints(const ArrayView& a, PointCloud& out, bool reject_non_finite,
                          const std::string& what) {
  const std::int64_t n = a.shape[0];
  out.resize(static_cast<std::size_t>(n));
  if (isPackedFloat32(a)) {
    std::memcpy(static_cast<void*>(out.data()), a.data, static_cast<std::size_t>(n) * 12);
  } else {
    for (std::int64_t i = 0; i < n; ++i) {
      out[i] = Point3f(static_cast<float>(at(a, i, 0)), static_cast<float>(at(a, i, 1)),
                       static_cast<float>(at(a, i, 2)));
    }
  }
  if (reject_non_finite) {
    for (std::size_t i = 0; i < out.size(); ++i) {
      if (!out[i].allFinite()) {
        return makeError(what + ": point " + std::to_string(i) + " is NaN or Inf");
      }
    }
  }
  return {};
}

Expected<Point3f> readPoint(const ArrayView& a, const std::string& what) {
  const bool flat = a.shape.size() == 1 && a.shape[0] == 3;
  const bool row = a.shape.size() == 2 && a.shape[0] == 1 && a.shape[1] == 3;
  if (!flat && !row) return makeError(what + " must be 3 numbers, got shape " + shapeText(a));
  if (auto ok = checkFloat(a, what); !ok) return std::unexpected(ok.error());
  ArrayView m = a;
  if (flat) {
    m.shape = {1, 3};
    m.strides = {0, a.strides[0]};
  }
  const Point3f p(static_cast<float>(at(m, 0, 0)), static_cast<float>(at(m, 0, 1)),
                  static_cast<float>(at(m, 0, 2)));
  if (!p.allFinite()) return makeError(what + " is NaN or Inf");
  return p;
}

Expected<std::array<double, 16>> readMatrix4(const ArrayView& a, const std::string& what) {
  if (a.shape.size() != 2 || a.shape[0] != 4 || a.shape[1] != 4) {
    return makeError(what + " must be a 4x4 matrix, got shape " + shapeText(a));
  }
  if (auto ok = checkFloat(a, what); !ok) return std::unexpected(ok.error());
  std::array<double, 16> m{};
  for (int r = 0; r < 4; ++r) {
    for (int c = 0; c < 4; ++c) m[r * 4 + c] = at(a, r, c);
  }
  return m;
}

}  // namespace densemap::python
