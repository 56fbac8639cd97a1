#include "densemap/raycast/ray_ends.hpp"

#include <algorithm>
#include <bit>
#include <cstdint>

#include "densemap/traversal/ray_traversal.hpp"  // hasFourLanes

#if defined(__x86_64__) && defined(__GNUC__)
#include <immintrin.h>
#define DENSEMAP_WIDE_ENDS 1
#endif

namespace densemap {
namespace {

#ifdef DENSEMAP_WIDE_ENDS
/// Four 64-bit lanes' masks as 32-bit ones.
[[gnu::target("avx2"), gnu::always_inline]] inline __m128i half(__m256d m) {
  return _mm256_castsi256_si128(_mm256_permutevar8x32_epi32(
      _mm256_castpd_si256(m), _mm256_setr_epi32(0, 2, 4, 6, 0, 2, 4, 6)));
}

/// One axis' keys of four coordinates (coordToKey: the float promoted, times the factor, within
/// [-kMaxKey, kMaxKey), floored, plus kMaxKey; 0 where outside): the keys as 32-bit lanes and
/// the lanes inside as all-ones.
[[gnu::target("avx2"), gnu::always_inline]] inline __m128i keysOfFour(__m128 coords, __m256d factor,
                                                                      __m128i& inside) {
  const __m256d scaled = _mm256_mul_pd(factor, _mm256_cvtps_pd(coords));
  const __m256d in =
      _mm256_and_pd(_mm256_cmp_pd(scaled, _mm256_set1_pd(-VoxelGrid::kMaxKey), _CMP_GE_OQ),
                    _mm256_cmp_pd(scaled, _mm256_set1_pd(VoxelGrid::kMaxKey), _CMP_LT_OQ));
  // floorToInt: the truncation, less one where it is above the value.
  const __m128i t = _mm256_cvttpd_epi32(scaled);
  const __m256d above = _mm256_cmp_pd(_mm256_cvtepi32_pd(t), scaled, _CMP_GT_OQ);
  inside = half(in);
  const __m128i key = _mm_add_epi32(_mm_add_epi32(t, half(above)),  // above: -1
                                    _mm_set1_epi32(VoxelGrid::kMaxKey));
  return _mm_and_si128(key, inside);
}

/// The eight points from `points`: their ray ends written where they are clearly within range;
/// returns the lanes left to rayEndInto.
[[gnu::target("avx2"), gnu::always_inline]] inline unsigned endsOfEight(
    const Point3f* points, __m256 ox, __m256 oy, __m256 oz, __m256d factor, double near_squared,
    bool unlimited, RayEnd* rays) {
  static_assert(sizeof(Point3f) == 3 * sizeof(float));
  const __m256i at = _mm256_setr_epi32(0, 3, 6, 9, 12, 15, 18, 21);
  const auto* base = reinterpret_cast<const float*>(points);
  const __m256 x = _mm256_i32gather_ps(base, at, 4);
  const __m256 y = _mm256_i32gather_ps(base + 1, at, 4);
  const __m256 z = _mm256_i32gather_ps(base + 2, at, 4);
  const __m256 dx = _mm256_sub_ps(x, ox), dy = _mm256_sub_ps(y, oy), dz = _mm256_sub_ps(z, oz);
  // (dx dx + dy dy) + dz dz in floats, as rayEndInto (no fused multiply-add in this target).
  const __m256 squared = _mm256_add_ps(_mm256_add_ps(_mm256_mul_ps(dx, dx), _mm256_mul_ps(dy, dy)),
                                       _mm256_mul_ps(dz, dz));
  const __m256d limit = _mm256_set1_pd(near_squared);
  const unsigned near_lo = static_cast<unsigned>(_mm256_movemask_pd(
      _mm256_cmp_pd(_mm256_cvtps_pd(_mm256_castps256_ps128(squared)), limit, _CMP_LT_OQ)));
  const unsigned near_hi = static_cast<unsigned>(_mm256_movemask_pd(
      _mm256_cmp_pd(_mm256_cvtps_pd(_mm256_extractf128_ps(squared, 1)), limit, _CMP_LT_OQ)));
  const unsigned near = unlimited ? 0xffU : near_lo | (near_hi << 4);
  if (near == 0) return 0xffU;
  __m128i in_x_lo, in_x_hi, in_y_lo, in_y_hi, in_z_lo, in_z_hi;
  alignas(32) std::int32_t kx[8], ky[8], kz[8], valid[8];
  _mm_store_si128(reinterpret_cast<__m128i*>(kx),
                  keysOfFour(_mm256_castps256_ps128(x), factor, in_x_lo));
  _mm_store_si128(reinterpret_cast<__m128i*>(kx + 4),
                  keysOfFour(_mm256_extractf128_ps(x, 1), factor, in_x_hi));
  _mm_store_si128(reinterpret_cast<__m128i*>(ky),
                  keysOfFour(_mm256_castps256_ps128(y), factor, in_y_lo));
  _mm_store_si128(reinterpret_cast<__m128i*>(ky + 4),
                  keysOfFour(_mm256_extractf128_ps(y, 1), factor, in_y_hi));
  _mm_store_si128(reinterpret_cast<__m128i*>(kz),
                  keysOfFour(_mm256_castps256_ps128(z), factor, in_z_lo));
  _mm_store_si128(reinterpret_cast<__m128i*>(kz + 4),
                  keysOfFour(_mm256_extractf128_ps(z, 1), factor, in_z_hi));
  _mm_store_si128(reinterpret_cast<__m128i*>(valid),
                  _mm_and_si128(in_x_lo, _mm_and_si128(in_y_lo, in_z_lo)));
  _mm_store_si128(reinterpret_cast<__m128i*>(valid + 4),
                  _mm_and_si128(in_x_hi, _mm_and_si128(in_y_hi, in_z_hi)));
  for (int k = 0; k < 8; ++k) {
    if (((near >> k) & 1U) == 0) continue;
    RayEnd& ray = rays[k];
    ray.weight = 1;
    ray.occupied = true;
    ray.end = points[k];
    ray.key_valid = valid[k] != 0;
    ray.key.x = static_cast<std::uint16_t>(kx[k]);
    ray.key.y = static_cast<std::uint16_t>(ky[k]);
    ray.key.z = static_cast<std::uint16_t>(kz[k]);
  }
  return ~near & 0xffU;
}

/// endsOfEight over the first n / 8 * 8 points; rest[g]: group g's lanes left to rayEndInto.
[[gnu::target("avx2")]] void endsByEight(const VoxelGrid& grid, const Point3f& origin,
                                         const Point3f* points, std::size_t n, double max_range_m,
                                         RayEnd* rays, std::uint8_t* rest) {
  const __m256 ox = _mm256_set1_ps(origin.x()), oy = _mm256_set1_ps(origin.y()),
               oz = _mm256_set1_ps(origin.z());
  const __m256d factor = _mm256_set1_pd(grid.resolutionFactor());
  // rayEndInto's test for a point clearly within range, the same double.
  const double near_squared = max_range_m * max_range_m * (1 - 0x1p-40);
  const bool unlimited = max_range_m < 0.0;
  for (std::size_t g = 0; g < n / 8; ++g) {
    rest[g] = static_cast<std::uint8_t>(
        endsOfEight(points + 8 * g, ox, oy, oz, factor, near_squared, unlimited, rays + 8 * g));
  }
}
#endif

}  // namespace

void rayEndsInto(const VoxelGrid& grid, const Point3f& origin, const Point3f* points, std::size_t n,
                 double max_range_m, RayEnd* rays) {
  std::size_t i = 0;
#ifdef DENSEMAP_WIDE_ENDS
  if (hasFourLanes()) {
    constexpr std::size_t kGroups = 64;  // points a pass: 8 kGroups
    std::uint8_t rest[kGroups];
    while (n - i >= 8) {
      const std::size_t m = std::min(n - i, 8 * kGroups) / 8 * 8;
      endsByEight(grid, origin, points + i, m, max_range_m, rays + i, rest);
      for (std::size_t g = 0; g < m / 8; ++g) {
        for (unsigned left = rest[g]; left != 0; left &= left - 1) {
          const std::size_t j = i + 8 * g + static_cast<std::size_t>(std::countr_zero(left));
          rayEndInto(grid, origin, points[j], max_range_m, rays[j]);
        }
      }
      i += m;
    }
  }
#endif
  for (; i < n; ++i) rayEndInto(grid, origin, points[i], max_range_m, rays[i]);
}

}  // namespace densemap
