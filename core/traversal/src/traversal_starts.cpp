// startTraversals: startTraversal and endOf for eight rays at a time in AVX-512 lanes (or AVX2
// lanes, the doubles in two halves of four) — the same
// IEEE operations in the same order (this file is built with -ffp-contract=off: no fused
// multiply-adds), so every time and decision is the scalar functions' bit for bit.
#include <cstdlib>
#include <cstring>
#include <limits>
#include <string_view>

#include "densemap/traversal/ray_traversal.hpp"

#if defined(__x86_64__) && defined(__GNUC__)
#include <immintrin.h>
#define DENSEMAP_WIDE_STARTS 1
#endif

namespace densemap {
namespace {

void startOne(const VoxelGrid& grid, const Point3f& origin, const VoxelKey& key_origin,
              const Point3f& end, const VoxelKey& key_end, TraversalStarts& out, int lane) {
  out.kind[lane] = startTraversal(grid, origin, key_origin, end, key_end, out.start[lane]);
  if (out.kind[lane] == TraversalKind::kRay) {
    out.end[lane] = endOf(out.start[lane], out.crossings[lane], &out.times[lane]);
  }
}

#ifdef DENSEMAP_WIDE_STARTS
#pragma GCC diagnostic push
#pragma GCC diagnostic ignored "-Wmaybe-uninitialized"
#pragma GCC diagnostic ignored "-Wuninitialized"  // GCC 12's intrinsics (its bug 105593)

/// The rays' ends and end keys in eight lanes (spare lanes: a copy of the first ray).
template <class Key>
void loadLanes(const Point3f* ends, const VoxelKey* key_ends, int n, float (&e)[3][8],
               Key (&k)[3][8]) {
  for (int i = 0; i < 8; ++i) {
    const int j = i < n ? i : 0;
    for (int a = 0; a < 3; ++a) {
      e[a][i] = ends[j][a];
      k[a][i] = key_ends[j][a];
    }
  }
}

/// Eight lanes' starts and ends (`r`, stored from the vectors) written out as startTraversal
/// and endOf give them.
template <class Int>
void writeOut(const TraversalLaneValues<Int>& r, const VoxelKey& key_origin,
              const VoxelKey* key_ends, int n, TraversalStarts& out) {
  for (int i = 0; i < n; ++i) {
    const unsigned bit = 1U << i;
    if ((r.same & bit) != 0 || (r.has_length & bit) == 0) {
      out.kind[i] = TraversalKind::kSameVoxel;
      continue;
    }
    out.kind[i] = TraversalKind::kRay;
    TraversalStart& s = out.start[i];
    s.origin = key_origin;
    s.end = key_ends[i];
    s.length = r.len[i];
    for (int a = 0; a < 3; ++a) {
      s.step[a] = static_cast<int>(r.st[a][i]);
      s.t_max[a] = r.tm[a][i];
      s.t_delta[a] = r.td[a][i];
      out.crossings[i][a] = static_cast<int>(r.cr[a][i]);
    }
    if ((r.irregular & bit) != 0) {
      out.end[i] = TraversalEnd::kIrregular;
    } else if ((r.unsure & bit) != 0) {
      out.end[i] = TraversalEnd::kUnsure;
    } else {
      out.end[i] = TraversalEnd::kClean;
      for (int a = 0; a < 3; ++a) out.times[i].last[a] = r.la[a][i];
      out.times[i].scale = r.sc[i];
    }
  }
}

/// endOf's near(x, y): |x - y| <= bound (NaN, from inf - inf: not near).
[[gnu::target("avx512f,avx512vl,avx512dq"), gnu::always_inline]] inline __mmask8 near(
    __m512d x, __m512d y, __m512d bound) {
  return _mm512_cmp_pd_mask(_mm512_andnot_pd(_mm512_set1_pd(-0.0), _mm512_sub_pd(x, y)), bound,
                            _CMP_LE_OQ);
}

/// Eight rays' starts and ends into lanes (`r`) with AVX-512: the doubles eight at a time, the
/// keys, steps and crossings as 64-bit ints in the vectors (exact: keys are 16-bit), stored as
/// TraversalLanes' 32-bit ones; the same IEEE operations in the same order as startTraversal
/// and endOf.
[[gnu::target("avx512f,avx512vl,avx512dq")]] void lanesEight(const VoxelGrid& grid,
                                                              const Point3f& origin,
                                                              const VoxelKey& key_origin,
                                                              const Point3f* ends,
                                                              const VoxelKey* key_ends, int n,
                                                              TraversalLanes& r) {
  constexpr double kMax = std::numeric_limits<double>::max();
  constexpr double kInf = std::numeric_limits<double>::infinity();
  alignas(32) float e[3][8];
  loadLanes(ends, key_ends, n, e, r.key_end);
  const int ko[3] = {key_origin.x, key_origin.y, key_origin.z};
  const double resolution = grid.resolution();
  // Vector3 arithmetic of OctoMap, one float operation at a time (as startTraversal).
  __m256 dir[3];
  for (int a = 0; a < 3; ++a) {
    dir[a] = _mm256_sub_ps(_mm256_load_ps(e[a]), _mm256_set1_ps(origin[a]));
  }
  const __m256 norm_sq = _mm256_add_ps(
      _mm256_add_ps(_mm256_mul_ps(dir[0], dir[0]), _mm256_mul_ps(dir[1], dir[1])),
      _mm256_mul_ps(dir[2], dir[2]));
  const __m256 length = _mm512_cvtpd_ps(_mm512_sqrt_pd(_mm512_cvtps_pd(norm_sq)));
  const __mmask8 has_length = _mm256_cmp_ps_mask(length, _mm256_setzero_ps(), _CMP_GT_OQ);
  __mmask8 same = 0xff;  // both ends in one voxel
  __m512d t_max[3], t_delta[3];
  __m512i step[3], key_end[3];
  for (int a = 0; a < 3; ++a) {
    key_end[a] = _mm512_cvtepi32_epi64(
        _mm256_load_si256(reinterpret_cast<const __m256i*>(r.key_end[a])));
    same &= _mm512_cmpeq_epi64_mask(key_end[a], _mm512_set1_epi64(ko[a]));
    const __m256 d = _mm256_div_ps(dir[a], length);
    const __mmask8 up = _mm256_cmp_ps_mask(d, _mm256_setzero_ps(), _CMP_GT_OQ);
    const __mmask8 down = _mm256_cmp_ps_mask(d, _mm256_setzero_ps(), _CMP_LT_OQ);
    step[a] = _mm512_mask_mov_epi64(
        _mm512_maskz_mov_epi64(up, _mm512_set1_epi64(1)), down, _mm512_set1_epi64(-1));
    // The voxel's border toward the step: the key's centre plus the (float) half step.
    const double centre = VoxelGrid::keyToCoord(ko[a], resolution);
    const double border_up = centre + static_cast<float>(1 * resolution * 0.5);
    const double border_down = centre + static_cast<float>(-1 * resolution * 0.5);
    const __m512d border =
        _mm512_mask_mov_pd(_mm512_set1_pd(border_up), down, _mm512_set1_pd(border_down));
    const __m512d dd = _mm512_cvtps_pd(d);
    const __m512d fabs_d = _mm512_cvtps_pd(_mm256_andnot_ps(_mm256_set1_ps(-0.0F), d));
    const auto moves = static_cast<__mmask8>(up | down);
    t_max[a] = _mm512_mask_div_pd(
        _mm512_set1_pd(kMax), moves,
        _mm512_sub_pd(border, _mm512_set1_pd(static_cast<double>(origin[a]))), dd);
    t_delta[a] =
        _mm512_mask_div_pd(_mm512_set1_pd(kMax), moves, _mm512_set1_pd(resolution), fabs_d);
  }
  // endOf, lane by lane in masks.
  __mmask8 irregular = 0;
  __m512d last[3], beyond[3];
  __m512d scale = _mm512_setzero_pd();
  __m512i total = _mm512_setzero_si512();
  __m512i crossings[3];
  for (int a = 0; a < 3; ++a) {
    const __m512i c =
        _mm512_mullo_epi64(_mm512_sub_epi64(key_end[a], _mm512_set1_epi64(ko[a])), step[a]);
    crossings[a] = c;
    const __mmask8 still = _mm512_cmpeq_epi64_mask(step[a], _mm512_setzero_si512());
    irregular |= _mm512_mask_cmpneq_epi64_mask(still, key_end[a], _mm512_set1_epi64(ko[a]));
    irregular |= _mm512_mask_cmplt_epi64_mask(static_cast<__mmask8>(~still), c,
                                              _mm512_setzero_si512());
    const auto moving = static_cast<__mmask8>(~still);
    total = _mm512_mask_add_epi64(total, moving, total, c);
    const __m512d cd = _mm512_cvtepi64_pd(c);
    beyond[a] = _mm512_mask_add_pd(_mm512_set1_pd(kInf), moving, t_max[a],
                                   _mm512_mul_pd(cd, t_delta[a]));
    const __mmask8 some = _mm512_mask_cmpgt_epi64_mask(moving, c, _mm512_setzero_si512());
    last[a] = _mm512_mask_add_pd(
        _mm512_set1_pd(-kInf), some, t_max[a],
        _mm512_mul_pd(_mm512_cvtepi64_pd(_mm512_sub_epi64(c, _mm512_set1_epi64(1))), t_delta[a]));
    const __m512d reach = _mm512_add_pd(
        _mm512_andnot_pd(_mm512_set1_pd(-0.0), t_max[a]),
        _mm512_mul_pd(_mm512_cvtepi64_pd(_mm512_add_epi64(c, _mm512_set1_epi64(1))), t_delta[a]));
    scale = _mm512_mask_max_pd(scale, moving, scale, reach);
  }
  // bound = 4 * (total + 8) * 2^-50 * scale (the int product first).
  const __m512d bound = _mm512_mul_pd(
      _mm512_mul_pd(_mm512_cvtepi64_pd(_mm512_mullo_epi64(
                        _mm512_add_epi64(total, _mm512_set1_epi64(8)), _mm512_set1_epi64(4))),
                    _mm512_set1_pd(0x1p-50)),
      scale);
  __mmask8 unsure = static_cast<__mmask8>(
      near(last[0], last[1], bound) | near(last[0], last[2], bound) |
      near(last[1], last[2], bound) | near(beyond[0], beyond[1], bound) |
      near(beyond[0], beyond[2], bound) | near(beyond[1], beyond[2], bound));
  const __m512d last_max = _mm512_max_pd(_mm512_max_pd(last[0], last[1]), last[2]);
  const __m512d beyond_min = _mm512_min_pd(_mm512_min_pd(beyond[0], beyond[1]), beyond[2]);
  const __mmask8 some_last = _mm512_cmp_pd_mask(last_max, _mm512_set1_pd(-kInf), _CMP_GT_OQ);
  const __mmask8 gap =
      _mm512_cmp_pd_mask(_mm512_sub_pd(beyond_min, last_max), bound, _CMP_GT_OQ);
  const __mmask8 within = _mm512_cmp_pd_mask(
      _mm512_sub_pd(_mm512_cvtps_pd(length), last_max), bound, _CMP_GT_OQ);
  unsure |= static_cast<__mmask8>(~(some_last & gap & within));
  for (int a = 0; a < 3; ++a) {
    _mm512_store_pd(r.tm[a], t_max[a]);
    _mm512_store_pd(r.td[a], t_delta[a]);
    _mm512_store_pd(r.la[a], last[a]);
    _mm256_store_si256(reinterpret_cast<__m256i*>(r.st[a]), _mm512_cvtepi64_epi32(step[a]));
    _mm256_store_si256(reinterpret_cast<__m256i*>(r.cr[a]), _mm512_cvtepi64_epi32(crossings[a]));
  }
  _mm512_store_pd(r.sc, scale);
  _mm256_store_ps(r.len, length);
  r.same = same;
  r.has_length = has_length;
  r.irregular = irregular;
  r.unsure = unsure;
}

/// startTraversals' eight rays with AVX-512 (lanesEight's lanes written out).
[[gnu::target("avx512f,avx512vl,avx512dq")]] void startEight(const VoxelGrid& grid,
                                                              const Point3f& origin,
                                                              const VoxelKey& key_origin,
                                                              const Point3f* ends,
                                                              const VoxelKey* key_ends, int n,
                                                              TraversalStarts& out) {
  TraversalLanes r;
  lanesEight(grid, origin, key_origin, ends, key_ends, n, r);
  writeOut(r, key_origin, key_ends, n, out);
}

#define DENSEMAP_AVX2 gnu::target("avx2")

/// The 64-bit lanes of half `h` of a vector of eight 32-bit lane masks (or ints), sign-extended.
[[DENSEMAP_AVX2, gnu::always_inline]] inline __m256i halfOf(__m256i v, int h) {
  return _mm256_cvtepi32_epi64(h == 0 ? _mm256_castsi256_si128(v) : _mm256_extracti128_si256(v, 1));
}
[[DENSEMAP_AVX2, gnu::always_inline]] inline __m256d halfAsDoubles(__m256i v, int h) {
  return _mm256_cvtepi32_pd(h == 0 ? _mm256_castsi256_si128(v) : _mm256_extracti128_si256(v, 1));
}
[[DENSEMAP_AVX2, gnu::always_inline]] inline __m128 halfOf(__m256 v, int h) {
  return h == 0 ? _mm256_castps256_ps128(v) : _mm256_extractf128_ps(v, 1);
}
[[DENSEMAP_AVX2, gnu::always_inline]] inline __m256d blendMask(__m256d no, __m256d yes, __m256i k) {
  return _mm256_blendv_pd(no, yes, _mm256_castsi256_pd(k));
}
[[DENSEMAP_AVX2, gnu::always_inline]] inline int bitsOf(__m256i k32) {
  return _mm256_movemask_ps(_mm256_castsi256_ps(k32));
}
/// endOf's near(x, y) for four lanes, as bits.
[[DENSEMAP_AVX2, gnu::always_inline]] inline int nearFour(__m256d x, __m256d y, __m256d bound) {
  return _mm256_movemask_pd(_mm256_cmp_pd(
      _mm256_andnot_pd(_mm256_set1_pd(-0.0), _mm256_sub_pd(x, y)), bound, _CMP_LE_OQ));
}

/// startEight with AVX2 into lanes: the floats in eight lanes, the doubles in two halves of
/// four, the keys, steps and crossings as 32-bit ints (exact: keys are 16-bit), the same IEEE
/// operations in the same order.
[[DENSEMAP_AVX2]] void lanesEightByFour(const VoxelGrid& grid, const Point3f& origin,
                                        const VoxelKey& key_origin, const Point3f* ends,
                                        const VoxelKey* key_ends, int n, TraversalLanes& r) {
  constexpr double kMax = std::numeric_limits<double>::max();
  constexpr double kInf = std::numeric_limits<double>::infinity();
  alignas(32) float e[3][8];
  std::int32_t(&k)[3][8] = r.key_end;
  loadLanes(ends, key_ends, n, e, k);
  const int ko[3] = {key_origin.x, key_origin.y, key_origin.z};
  const double resolution = grid.resolution();
  __m256 dir[3];
  for (int a = 0; a < 3; ++a) {
    dir[a] = _mm256_sub_ps(_mm256_load_ps(e[a]), _mm256_set1_ps(origin[a]));
  }
  const __m256 norm_sq =
      _mm256_add_ps(_mm256_add_ps(_mm256_mul_ps(dir[0], dir[0]), _mm256_mul_ps(dir[1], dir[1])),
                    _mm256_mul_ps(dir[2], dir[2]));
  const __m256 length =
      _mm256_set_m128(_mm256_cvtpd_ps(_mm256_sqrt_pd(_mm256_cvtps_pd(halfOf(norm_sq, 1)))),
                      _mm256_cvtpd_ps(_mm256_sqrt_pd(_mm256_cvtps_pd(halfOf(norm_sq, 0)))));
  const int has_length = _mm256_movemask_ps(_mm256_cmp_ps(length, _mm256_setzero_ps(), _CMP_GT_OQ));
  const __m256i zero = _mm256_setzero_si256();
  int same = 0xff, irregular = 0;
  __m256d t_max[3][2], t_delta[3][2], last[3][2], beyond[3][2];
  __m256d scale[2] = {_mm256_setzero_pd(), _mm256_setzero_pd()};
  __m256i step[3], crossings[3];
  __m256i total = zero;
  for (int a = 0; a < 3; ++a) {
    const __m256i key_end = _mm256_load_si256(reinterpret_cast<const __m256i*>(k[a]));
    const __m256i key_o = _mm256_set1_epi32(ko[a]);
    same &= bitsOf(_mm256_cmpeq_epi32(key_end, key_o));
    const __m256 d = _mm256_div_ps(dir[a], length);
    const __m256i up = _mm256_castps_si256(_mm256_cmp_ps(d, _mm256_setzero_ps(), _CMP_GT_OQ));
    const __m256i down = _mm256_castps_si256(_mm256_cmp_ps(d, _mm256_setzero_ps(), _CMP_LT_OQ));
    step[a] = _mm256_sub_epi32(down, up);  // -1 - 0 down, 0 - -1 up
    const __m256i moves = _mm256_or_si256(up, down);
    const double centre = VoxelGrid::keyToCoord(ko[a], resolution);
    const double border_up = centre + static_cast<float>(1 * resolution * 0.5);
    const double border_down = centre + static_cast<float>(-1 * resolution * 0.5);
    // endOf's crossings: (key_end - key_origin) * step.
    const __m256i c = _mm256_sign_epi32(_mm256_sub_epi32(key_end, key_o), step[a]);
    crossings[a] = c;
    irregular |= bitsOf(_mm256_andnot_si256(
        moves, _mm256_xor_si256(_mm256_cmpeq_epi32(key_end, key_o), _mm256_set1_epi32(-1))));
    irregular |= bitsOf(_mm256_and_si256(moves, _mm256_cmpgt_epi32(zero, c)));
    total = _mm256_add_epi32(total, _mm256_and_si256(moves, c));
    const __m256i some = _mm256_and_si256(moves, _mm256_cmpgt_epi32(c, zero));
    const __m256i c_less = _mm256_sub_epi32(c, _mm256_set1_epi32(1));
    const __m256i c_more = _mm256_add_epi32(c, _mm256_set1_epi32(1));
    for (int h = 0; h < 2; ++h) {
      const __m128 dh = halfOf(d, h);
      const __m256d dd = _mm256_cvtps_pd(dh);
      const __m256d fabs_d = _mm256_cvtps_pd(_mm_andnot_ps(_mm_set1_ps(-0.0F), dh));
      const __m256i moves64 = halfOf(moves, h);
      const __m256d border =
          blendMask(_mm256_set1_pd(border_up), _mm256_set1_pd(border_down), halfOf(down, h));
      const __m256d tm = blendMask(
          _mm256_set1_pd(kMax),
          _mm256_div_pd(_mm256_sub_pd(border, _mm256_set1_pd(static_cast<double>(origin[a]))), dd),
          moves64);
      const __m256d td = blendMask(_mm256_set1_pd(kMax),
                                   _mm256_div_pd(_mm256_set1_pd(resolution), fabs_d), moves64);
      t_max[a][h] = tm;
      t_delta[a][h] = td;
      beyond[a][h] = blendMask(_mm256_set1_pd(kInf),
                               _mm256_add_pd(tm, _mm256_mul_pd(halfAsDoubles(c, h), td)), moves64);
      last[a][h] = blendMask(_mm256_set1_pd(-kInf),
                             _mm256_add_pd(tm, _mm256_mul_pd(halfAsDoubles(c_less, h), td)),
                             halfOf(some, h));
      const __m256d reach = _mm256_add_pd(_mm256_andnot_pd(_mm256_set1_pd(-0.0), tm),
                                          _mm256_mul_pd(halfAsDoubles(c_more, h), td));
      scale[h] = blendMask(scale[h], _mm256_max_pd(scale[h], reach), moves64);
    }
  }
  // bound = 4 * (total + 8) * 2^-50 * scale (the int product first).
  const __m256i total_term = _mm256_slli_epi32(_mm256_add_epi32(total, _mm256_set1_epi32(8)), 2);
  r.unsure = 0;
  for (int h = 0; h < 2; ++h) {
    const __m256d bound = _mm256_mul_pd(
        _mm256_mul_pd(halfAsDoubles(total_term, h), _mm256_set1_pd(0x1p-50)), scale[h]);
    int u = nearFour(last[0][h], last[1][h], bound) | nearFour(last[0][h], last[2][h], bound) |
            nearFour(last[1][h], last[2][h], bound) | nearFour(beyond[0][h], beyond[1][h], bound) |
            nearFour(beyond[0][h], beyond[2][h], bound) |
            nearFour(beyond[1][h], beyond[2][h], bound);
    const __m256d last_max = _mm256_max_pd(_mm256_max_pd(last[0][h], last[1][h]), last[2][h]);
    const __m256d beyond_min =
        _mm256_min_pd(_mm256_min_pd(beyond[0][h], beyond[1][h]), beyond[2][h]);
    const __m256d some_last = _mm256_cmp_pd(last_max, _mm256_set1_pd(-kInf), _CMP_GT_OQ);
    const __m256d gap = _mm256_cmp_pd(_mm256_sub_pd(beyond_min, last_max), bound, _CMP_GT_OQ);
    const __m256d within = _mm256_cmp_pd(
        _mm256_sub_pd(_mm256_cvtps_pd(halfOf(length, h)), last_max), bound, _CMP_GT_OQ);
    u |= ~_mm256_movemask_pd(_mm256_and_pd(some_last, _mm256_and_pd(gap, within))) & 0xf;
    r.unsure |= static_cast<unsigned>(u) << (4 * h);
    for (int a = 0; a < 3; ++a) {
      _mm256_store_pd(r.tm[a] + 4 * h, t_max[a][h]);
      _mm256_store_pd(r.td[a] + 4 * h, t_delta[a][h]);
      _mm256_store_pd(r.la[a] + 4 * h, last[a][h]);
    }
    _mm256_store_pd(r.sc + 4 * h, scale[h]);
  }
  for (int a = 0; a < 3; ++a) {
    _mm256_store_si256(reinterpret_cast<__m256i*>(r.st[a]), step[a]);
    _mm256_store_si256(reinterpret_cast<__m256i*>(r.cr[a]), crossings[a]);
  }
  _mm256_store_ps(r.len, length);
  r.same = static_cast<unsigned>(same);
  r.has_length = static_cast<unsigned>(has_length);
  r.irregular = static_cast<unsigned>(irregular);
}

/// startEight with AVX2 (lanesEightByFour's lanes written out).
[[DENSEMAP_AVX2]] void startEightByFour(const VoxelGrid& grid, const Point3f& origin,
                                        const VoxelKey& key_origin, const Point3f* ends,
                                        const VoxelKey* key_ends, int n, TraversalStarts& out) {
  TraversalLanes r;
  lanesEightByFour(grid, origin, key_origin, ends, key_ends, n, r);
  writeOut(r, key_origin, key_ends, n, out);
}
#undef DENSEMAP_AVX2
#pragma GCC diagnostic pop
#endif

}  // namespace

int laneCap() {
  static const int cap = [] {
    const char* value = std::getenv("DENSEMAP_LANES");
    if (value == nullptr) return 512;
    const std::string_view v(value);
    return v == "256" ? 256 : v == "0" ? 0 : 512;
  }();
  return cap;
}

bool hasWideLanes() {
#ifdef DENSEMAP_WIDE_STARTS
  static const bool has = [] {
    __builtin_cpu_init();
    return laneCap() >= 512 && __builtin_cpu_supports("avx512f") != 0 &&
           __builtin_cpu_supports("avx512vl") != 0 && __builtin_cpu_supports("avx512dq") != 0;
  }();
  return has;
#else
  return false;
#endif
}

bool hasFourLanes() {
#ifdef DENSEMAP_WIDE_STARTS
  static const bool has = [] {
    __builtin_cpu_init();
    return laneCap() >= 256 && __builtin_cpu_supports("avx2") != 0;
  }();
  return has;
#else
  return false;
#endif
}

void startTraversalLanes(const VoxelGrid& grid, const Point3f& origin, const VoxelKey& key_origin,
                         const Point3f* ends, const VoxelKey* key_ends, int n,
                         TraversalLanes& out, bool wide) {
  if (n <= 0) return;
#ifdef DENSEMAP_WIDE_STARTS
  if (wide && hasWideLanes()) {
    lanesEight(grid, origin, key_origin, ends, key_ends, n, out);
    return;
  }
  if (hasFourLanes()) {
    lanesEightByFour(grid, origin, key_origin, ends, key_ends, n, out);
    return;
  }
#endif
  (void)grid, (void)origin, (void)key_origin, (void)ends, (void)key_ends, (void)wide;
  out.same = 0;
  out.has_length = 0xffU;
  out.irregular = 0xffU;
}

void startTraversals(const VoxelGrid& grid, const Point3f& origin, const VoxelKey& key_origin,
                     const Point3f* ends, const VoxelKey* key_ends, int n, TraversalStarts& out,
                     bool wide) {
  if (n <= 0) return;
#ifdef DENSEMAP_WIDE_STARTS
  if (wide && hasWideLanes()) {
    startEight(grid, origin, key_origin, ends, key_ends, n, out);
    return;
  }
  if (wide && hasFourLanes()) {
    startEightByFour(grid, origin, key_origin, ends, key_ends, n, out);
    return;
  }
#endif
  (void)wide;
  for (int i = 0; i < n; ++i) startOne(grid, origin, key_origin, ends[i], key_ends[i], out, i);
}

}  // namespace densemap
