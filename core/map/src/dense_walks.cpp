// DenseMarks::markQueued and markQueuedBack: the queued walks' steps, one walk at a time, or
// eight side by side in AVX-512 lanes, or (forward walks) four in AVX2 lanes (the same decisions
// from the same double arithmetic, the same marks).
#include <algorithm>
#include <bit>
#include <cstddef>
#include <cstring>
#include <limits>

#include "densemap/geometry/ray_traversal.hpp"
#include "densemap/map/dense_marks.hpp"

#if defined(__x86_64__) && defined(__GNUC__)
#include <immintrin.h>
#define DENSEMAP_WIDE_WALKS 1
#endif

namespace densemap {
namespace {

/// Steps on a queued walk's place (as DenseMarks::Cursor::move), marking each voxel — unless
/// `culled` holds it, which stops the walk — with the blocks entered listed for the first-touch
/// bookkeeping afterwards.
struct PlaceSteps {
  std::uint64_t* words;
  const std::uint64_t* culled;  // null: none
  std::uint32_t* entered;
  std::size_t n_entered = 0;
  std::size_t marked = 0;
  DenseMarks::WalkPlace at;
  template <int A>
  [[gnu::always_inline]] bool step() {
    if (--at.left[A] == 0) {
      at.left[A] = block::kEdge;
      at.addr += static_cast<std::uint64_t>(static_cast<std::int64_t>(at.wrap[A]));
      entered[n_entered++] = static_cast<std::uint32_t>(at.addr >> 9);
    } else {
      at.addr += static_cast<std::uint64_t>(static_cast<std::int64_t>(at.small[A]));
    }
    const std::uint64_t bit = std::uint64_t{1} << (at.addr & 63U);
    if (culled != nullptr && (culled[at.addr >> 6] & bit) != 0) return false;
    words[at.addr >> 6] |= bit;
    ++marked;
    return true;
  }
};

#ifdef DENSEMAP_WIDE_WALKS
// GCC 12's AVX-512 intrinsics start some results from _mm512_undefined_* (its bug 105593).
#pragma GCC diagnostic push
#pragma GCC diagnostic ignored "-Wmaybe-uninitialized"
#pragma GCC diagnostic ignored "-Wuninitialized"
#define DENSEMAP_AVX512 gnu::target("avx512f,avx512vl,avx512dq")

/// Writes the lanes' words and marks, packed, at `w` and `b` (8 slots each); returns how many.
[[DENSEMAP_AVX512, gnu::always_inline]] inline std::size_t pendLanes(__mmask8 lanes, __m512i words,
                                                                     __m512i bits, std::uint64_t* w,
                                                                     std::uint64_t* b) {
  _mm512_storeu_si512(w, _mm512_maskz_compress_epi64(lanes, words));
  _mm512_storeu_si512(b, _mm512_maskz_compress_epi64(lanes, bits));
  return static_cast<std::size_t>(std::popcount(static_cast<unsigned>(lanes)));
}

/// Eight walks' places, a lane each, moved along the axes their lanes chose.
struct LanePlaces {
  __m512i addr, l0, l1, l2, s0, s1, s2, r0, r1, r2;
  /// Puts walk place `at` in lane(s) `k`.
  [[DENSEMAP_AVX512, gnu::always_inline]] void load(__mmask8 k, const DenseMarks::WalkPlace& at) {
    addr = _mm512_mask_set1_epi64(addr, k, static_cast<long long>(at.addr));
    l0 = _mm512_mask_set1_epi64(l0, k, at.left[0]);
    l1 = _mm512_mask_set1_epi64(l1, k, at.left[1]);
    l2 = _mm512_mask_set1_epi64(l2, k, at.left[2]);
    s0 = _mm512_mask_set1_epi64(s0, k, at.small[0]);
    s1 = _mm512_mask_set1_epi64(s1, k, at.small[1]);
    s2 = _mm512_mask_set1_epi64(s2, k, at.small[2]);
    r0 = _mm512_mask_set1_epi64(r0, k, at.wrap[0]);
    r1 = _mm512_mask_set1_epi64(r1, k, at.wrap[1]);
    r2 = _mm512_mask_set1_epi64(r2, k, at.wrap[2]);
  }
  /// The lanes in m0 / m1 / m2 step along axis 0 / 1 / 2; the blocks entered are written packed
  /// at `entered` (8 slots); returns how many.
  [[DENSEMAP_AVX512, gnu::always_inline]] std::size_t move(__mmask8 m0, __mmask8 m1, __mmask8 m2,
                                                           std::uint32_t* entered) {
    const __m512i one = _mm512_set1_epi64(1), zero = _mm512_setzero_si512();
    l0 = _mm512_mask_sub_epi64(l0, m0, l0, one);
    l1 = _mm512_mask_sub_epi64(l1, m1, l1, one);
    l2 = _mm512_mask_sub_epi64(l2, m2, l2, one);
    const __mmask8 w0 = _mm512_mask_cmpeq_epi64_mask(m0, l0, zero);
    const __mmask8 w1 = _mm512_mask_cmpeq_epi64_mask(m1, l1, zero);
    const __mmask8 w2 = _mm512_mask_cmpeq_epi64_mask(m2, l2, zero);
    __m512i inc = _mm512_maskz_mov_epi64(m0, s0);
    inc = _mm512_mask_mov_epi64(inc, m1, s1);
    inc = _mm512_mask_mov_epi64(inc, m2, s2);
    inc = _mm512_mask_mov_epi64(inc, w0, r0);
    inc = _mm512_mask_mov_epi64(inc, w1, r1);
    inc = _mm512_mask_mov_epi64(inc, w2, r2);
    addr = _mm512_add_epi64(addr, inc);
    const __m512i edge = _mm512_set1_epi64(block::kEdge);
    l0 = _mm512_mask_mov_epi64(l0, w0, edge);
    l1 = _mm512_mask_mov_epi64(l1, w1, edge);
    l2 = _mm512_mask_mov_epi64(l2, w2, edge);
    const auto wrapped = static_cast<__mmask8>(w0 | w1 | w2);
    const __m256i blocks = _mm512_cvtepi64_epi32(_mm512_srli_epi64(addr, 9));
    _mm256_storeu_si256(reinterpret_cast<__m256i*>(entered),
                        _mm256_maskz_compress_epi32(wrapped, blocks));
    return static_cast<std::size_t>(std::popcount(static_cast<unsigned>(wrapped)));
  }
};

/// Buffers of a wide walk: blocks entered, and marks gathered per lane and word, pended when the
/// lane moves to another word (the word's ORs one after the other would wait on each other).
struct WideOut {
  std::uint32_t* entered;
  std::uint64_t* pend_w;
  std::uint64_t* pend_b;
  std::size_t n_entered = 0;
  std::size_t n_pend = 0;
};

/// The forward walks' steps eight at a time, one walk a lane: countedSteps' choice (the smallest
/// tMax, ties to the higher axis) as compare masks; a lane whose walk is done takes the next one,
/// so the lanes' walks are at different distances from their (shared) origin and their marks
/// seldom fall on one word. `out` must have room for (all the walks' steps + 1) + 16.
[[DENSEMAP_AVX512]] void walkEight(const DenseMarks::QueuedWalk* walks, std::size_t n,
                                   WideOut& out) {
  const __m512i one = _mm512_set1_epi64(1), zero = _mm512_setzero_si512(),
                low6 = _mm512_set1_epi64(63);
  __m512d t0 = _mm512_setzero_pd(), t1 = t0, t2 = t0, d0 = t0, d1 = t0, d2 = t0;
  LanePlaces p{zero, zero, zero, zero, zero, zero, zero, zero, zero, zero};
  __m512i left = zero;                 // the lane's steps to go
  __m512i cur_w = zero, cur_b = zero;  // the word being marked, its marks so far
  __mmask8 live = 0;                   // lanes with a walk whose last marks are not pended
  std::size_t next = 0;
  while (true) {
    __mmask8 active = _mm512_cmpgt_epi64_mask(left, zero);
    if (active != 0xff) {
      const auto done = static_cast<__mmask8>(live & ~active);
      out.n_pend += pendLanes(done, cur_w, cur_b, out.pend_w + out.n_pend, out.pend_b + out.n_pend);
      cur_b = _mm512_maskz_mov_epi64(active, cur_b);
      // Idle lanes take the next walks.
      auto idle = static_cast<unsigned>(static_cast<__mmask8>(~active));
      for (; idle != 0 && next < n; idle &= idle - 1, ++next) {
        const DenseMarks::QueuedWalk& w = walks[next];
        const auto k = static_cast<__mmask8>(idle & (0U - idle));
        t0 = _mm512_mask_broadcastsd_pd(t0, k, _mm_set_sd(w.t_max[0]));
        t1 = _mm512_mask_broadcastsd_pd(t1, k, _mm_set_sd(w.t_max[1]));
        t2 = _mm512_mask_broadcastsd_pd(t2, k, _mm_set_sd(w.t_max[2]));
        d0 = _mm512_mask_broadcastsd_pd(d0, k, _mm_set_sd(w.t_delta[0]));
        d1 = _mm512_mask_broadcastsd_pd(d1, k, _mm_set_sd(w.t_delta[1]));
        d2 = _mm512_mask_broadcastsd_pd(d2, k, _mm_set_sd(w.t_delta[2]));
        p.load(k, w.at);
        left = _mm512_mask_set1_epi64(left, k, w.steps);
        cur_w = _mm512_mask_set1_epi64(cur_w, k, static_cast<long long>(w.at.addr >> 6));
      }
      active = _mm512_cmpgt_epi64_mask(left, zero);
      live = active;
      if (active == 0) break;
    }
    left = _mm512_mask_sub_epi64(left, active, left, one);
    const __mmask8 lt01 = _mm512_cmp_pd_mask(t0, t1, _CMP_LT_OQ);
    const __mmask8 lt02 = _mm512_cmp_pd_mask(t0, t2, _CMP_LT_OQ);
    const __mmask8 lt12 = _mm512_cmp_pd_mask(t1, t2, _CMP_LT_OQ);
    const auto m0 = static_cast<__mmask8>(active & lt01 & lt02);
    const auto m1 = static_cast<__mmask8>(active & ~lt01 & lt12);
    const auto m2 = static_cast<__mmask8>(active & ~(m0 | m1));
    t0 = _mm512_mask_add_pd(t0, m0, t0, d0);
    t1 = _mm512_mask_add_pd(t1, m1, t1, d1);
    t2 = _mm512_mask_add_pd(t2, m2, t2, d2);
    out.n_entered += p.move(m0, m1, m2, out.entered + out.n_entered);
    const __m512i word = _mm512_srli_epi64(p.addr, 6);
    const __mmask8 moved = _mm512_mask_cmpneq_epi64_mask(active, word, cur_w);
    out.n_pend += pendLanes(moved, cur_w, cur_b, out.pend_w + out.n_pend, out.pend_b + out.n_pend);
    cur_w = _mm512_mask_mov_epi64(cur_w, moved, word);
    cur_b = _mm512_mask_mov_epi64(cur_b, moved, zero);
    cur_b = _mm512_mask_or_epi64(cur_b, active, cur_b,
                                 _mm512_sllv_epi64(one, _mm512_and_si512(p.addr, low6)));
  }
}

/// The backward walks' steps eight at a time, one walk a lane: backwardSteps' decision (the
/// latest head, ties to the lower axis, winning by more than the bound, else the walk is handed
/// over) as compare masks; a lane stops at a voxel `culled` holds. The region's word of a
/// lane's voxel is gathered when the lane moves to another word, and the voxel is tested (and
/// marked) one iteration later, after the next step's decision: the gather's wait overlaps that
/// work instead of holding up every step (a lane that stops has moved one voxel on, unmarked,
/// and is dropped). Returns the counts of the walks not handed over; their ids go to
/// `handed_over`.
[[DENSEMAP_AVX512]] DenseMarks::BackWalkCounts walkEightBack(
    const DenseMarks::QueuedBackWalk* walks, std::size_t n, const std::uint64_t* culled,
    WideOut& out, std::vector<std::uint32_t>& handed_over) {
  const __m512i one = _mm512_set1_epi64(1), zero = _mm512_setzero_si512(),
                low6 = _mm512_set1_epi64(63);
  const __m512d none = _mm512_set1_pd(-std::numeric_limits<double>::infinity());
  __m512d h0 = _mm512_setzero_pd(), h1 = h0, h2 = h0, d0 = h0, d1 = h0, d2 = h0, bound = h0;
  __m512i n0 = zero, n1 = zero, n2 = zero;  // crossings left per axis (next, as BackwardWalk)
  LanePlaces p{zero, zero, zero, zero, zero, zero, zero, zero, zero, zero};
  __m512i left = zero, marked = zero;
  __m512i cur_w = zero, cur_b = zero, cur_r = zero;  // cur_r: the region's bits of cur_w
  __m512i pending = zero;  // the bit of the voxel moved to and not yet tested (0: none)
  __mmask8 live = 0, handing = 0;
  std::size_t lane_walk[8] = {0, 0, 0, 0, 0, 0, 0, 0};
  std::size_t next = 0;
  DenseMarks::BackWalkCounts counts;
  alignas(64) std::int64_t marked_at[8];
  while (true) {
    __mmask8 active = _mm512_cmpgt_epi64_mask(left, zero);
    __mmask8 tested = _mm512_test_epi64_mask(pending, pending);
    if (static_cast<__mmask8>(active | tested) != 0xff) {
      const auto done = static_cast<__mmask8>(live & ~(active | tested));
      out.n_pend += pendLanes(done, cur_w, cur_b, out.pend_w + out.n_pend, out.pend_b + out.n_pend);
      if (done != 0) {
        _mm512_store_si512(marked_at, marked);
        for (unsigned d = done; d != 0; d &= d - 1) {
          const int k = std::countr_zero(d);
          const DenseMarks::QueuedBackWalk& w = walks[lane_walk[k]];
          if (((handing >> k) & 1U) != 0) {
            handed_over.push_back(w.id);
          } else {
            counts.visits += static_cast<std::size_t>(marked_at[k]);
            counts.culled += static_cast<std::size_t>(w.total - marked_at[k]);
          }
        }
        handing = static_cast<__mmask8>(handing & ~done);
      }
      const auto busy = static_cast<__mmask8>(active | tested);
      cur_b = _mm512_maskz_mov_epi64(busy, cur_b);
      marked = _mm512_maskz_mov_epi64(busy, marked);
      auto idle = static_cast<unsigned>(static_cast<__mmask8>(~busy));
      for (; idle != 0 && next < n; idle &= idle - 1, ++next) {
        const DenseMarks::QueuedBackWalk& w = walks[next];
        const auto k = static_cast<__mmask8>(idle & (0U - idle));
        lane_walk[std::countr_zero(idle)] = next;
        h0 = _mm512_mask_broadcastsd_pd(h0, k, _mm_set_sd(w.head[0]));
        h1 = _mm512_mask_broadcastsd_pd(h1, k, _mm_set_sd(w.head[1]));
        h2 = _mm512_mask_broadcastsd_pd(h2, k, _mm_set_sd(w.head[2]));
        d0 = _mm512_mask_broadcastsd_pd(d0, k, _mm_set_sd(w.t_delta[0]));
        d1 = _mm512_mask_broadcastsd_pd(d1, k, _mm_set_sd(w.t_delta[1]));
        d2 = _mm512_mask_broadcastsd_pd(d2, k, _mm_set_sd(w.t_delta[2]));
        bound = _mm512_mask_broadcastsd_pd(bound, k, _mm_set_sd(w.bound));
        n0 = _mm512_mask_set1_epi64(n0, k, w.next[0]);
        n1 = _mm512_mask_set1_epi64(n1, k, w.next[1]);
        n2 = _mm512_mask_set1_epi64(n2, k, w.next[2]);
        p.load(k, w.at);
        left = _mm512_mask_set1_epi64(left, k, w.total);
        const std::uint64_t word = w.at.addr >> 6;
        cur_w = _mm512_mask_set1_epi64(cur_w, k, static_cast<long long>(word));
        cur_r = _mm512_mask_set1_epi64(cur_r, k, static_cast<long long>(culled[word]));
      }
      active = _mm512_cmpgt_epi64_mask(left, zero);
      live = static_cast<__mmask8>(active | tested);
      if (live == 0) break;
    }
    // The next step's decision: the latest crossing (ties to the lower axis), the runner-up.
    const __m512d high01 = _mm512_max_pd(h0, h1);
    const __mmask8 m2 = _mm512_mask_cmp_pd_mask(active, h2, high01, _CMP_GT_OQ);
    const __mmask8 ge01 = _mm512_cmp_pd_mask(h0, h1, _CMP_GE_OQ);
    __mmask8 m0 = static_cast<__mmask8>(active & ~m2 & ge01);
    __mmask8 m1 = static_cast<__mmask8>(active & ~m2 & ~ge01);
    __m512d chosen = _mm512_mask_mov_pd(h1, m0, h0);
    chosen = _mm512_mask_mov_pd(chosen, m2, h2);
    __m512d runner = _mm512_max_pd(h0, h2);  // axis 1's
    runner = _mm512_mask_mov_pd(runner, m0, _mm512_max_pd(h1, h2));
    runner = _mm512_mask_mov_pd(runner, m2, high01);
    const __mmask8 wins =
        _mm512_mask_cmp_pd_mask(active, _mm512_sub_pd(chosen, runner), bound, _CMP_GT_OQ);
    // The voxel moved to last time: in the region (the walk ends there), else marked.
    const __mmask8 stop = _mm512_mask_test_epi64_mask(tested, cur_r, pending);
    const auto mark = static_cast<__mmask8>(tested & ~stop);
    cur_b = _mm512_mask_or_epi64(cur_b, mark, cur_b, pending);
    marked = _mm512_mask_add_epi64(marked, mark, marked, one);
    const auto go = static_cast<__mmask8>(active & ~stop);
    handing = static_cast<__mmask8>(handing | (go & ~wins));
    m0 = static_cast<__mmask8>(m0 & wins & ~stop);
    m1 = static_cast<__mmask8>(m1 & wins & ~stop);
    const auto m2w = static_cast<__mmask8>(m2 & wins & ~stop);
    const auto steps = static_cast<__mmask8>(m0 | m1 | m2w);
    // Lanes that stopped or hand over take no more steps.
    left = _mm512_maskz_mov_epi64(steps, left);
    // head = --next >= 0 ? head - delta : -inf
    n0 = _mm512_mask_sub_epi64(n0, m0, n0, one);
    n1 = _mm512_mask_sub_epi64(n1, m1, n1, one);
    n2 = _mm512_mask_sub_epi64(n2, m2w, n2, one);
    h0 = _mm512_mask_sub_pd(h0, m0, h0, d0);
    h1 = _mm512_mask_sub_pd(h1, m1, h1, d1);
    h2 = _mm512_mask_sub_pd(h2, m2w, h2, d2);
    h0 = _mm512_mask_mov_pd(h0, _mm512_mask_cmplt_epi64_mask(m0, n0, zero), none);
    h1 = _mm512_mask_mov_pd(h1, _mm512_mask_cmplt_epi64_mask(m1, n1, zero), none);
    h2 = _mm512_mask_mov_pd(h2, _mm512_mask_cmplt_epi64_mask(m2w, n2, zero), none);
    out.n_entered += p.move(m0, m1, m2w, out.entered + out.n_entered);
    left = _mm512_mask_sub_epi64(left, steps, left, one);
    const __m512i word = _mm512_srli_epi64(p.addr, 6);
    const __mmask8 moved = _mm512_mask_cmpneq_epi64_mask(steps, word, cur_w);
    out.n_pend += pendLanes(moved, cur_w, cur_b, out.pend_w + out.n_pend, out.pend_b + out.n_pend);
    cur_w = _mm512_mask_mov_epi64(cur_w, moved, word);
    cur_b = _mm512_mask_mov_epi64(cur_b, moved, zero);
    cur_r = _mm512_mask_i64gather_epi64(cur_r, moved, word, culled, 8);
    pending = _mm512_maskz_sllv_epi64(steps, one, _mm512_and_si512(p.addr, low6));
  }
  return counts;
}
#undef DENSEMAP_AVX512

#define DENSEMAP_AVX2 gnu::target("avx2")

/// AVX2 has no mask registers and no compress: a lane mask is a vector of all-ones lanes, and
/// the lanes a 4-bit mask names are packed to the front by a permute from these tables.
struct FourLaneTables {
  alignas(32) std::int32_t pack64[16][8];  // the 64-bit lanes set in the mask, in order
  alignas(32) std::int64_t lane[4][4];     // all-ones in lane k only
};
constexpr FourLaneTables makeFourLaneTables() {
  FourLaneTables t{};
  for (int m = 0; m < 16; ++m) {
    int n = 0;
    for (int i = 0; i < 4; ++i) {
      if ((m >> i & 1) == 0) continue;
      t.pack64[m][2 * n] = 2 * i;
      t.pack64[m][2 * n + 1] = 2 * i + 1;
      ++n;
    }
  }
  for (int k = 0; k < 4; ++k) t.lane[k][k] = -1;
  return t;
}
constexpr FourLaneTables kFour = makeFourLaneTables();

/// Writes the 64-bit lanes `bits` names of `v`, packed, at `out` (4 slots); returns how many.
[[DENSEMAP_AVX2, gnu::always_inline]] inline std::size_t packFour(int bits, __m256i v,
                                                                  std::uint64_t* out) {
  const __m256i idx = _mm256_load_si256(reinterpret_cast<const __m256i*>(kFour.pack64[bits]));
  _mm256_storeu_si256(reinterpret_cast<__m256i*>(out), _mm256_permutevar8x32_epi32(v, idx));
  return static_cast<std::size_t>(std::popcount(static_cast<unsigned>(bits)));
}

/// The lanes a vector mask holds, as bits.
[[DENSEMAP_AVX2, gnu::always_inline]] inline int bitsOf(__m256i m) {
  return _mm256_movemask_pd(_mm256_castsi256_pd(m));
}
/// `x` into the lanes `k` holds.
[[DENSEMAP_AVX2, gnu::always_inline]] inline void putLanes(__m256i& v, long long x, __m256i k) {
  v = _mm256_blendv_epi8(v, _mm256_set1_epi64x(x), k);
}
/// Pends the words and marks of the lanes `bits` names (packed at the pointers, which move on).
[[DENSEMAP_AVX2, gnu::always_inline]] inline void pendFour(int bits, __m256i words, __m256i marks,
                                                           std::uint64_t*& pend_w,
                                                           std::uint64_t*& pend_b) {
  packFour(bits, words, pend_w);
  const std::size_t pended = packFour(bits, marks, pend_b);
  pend_w += pended;
  pend_b += pended;
}

/// Four walks' places, a lane each, in mirrored block addresses (5 vectors where LanePlaces'
/// layout takes 10: AVX2 has 16 registers, and the walks' other state takes 9 more). Along an
/// axis a walk moves down, the voxel's coordinate in its block is kept as 7 - c (the axis' 3
/// bits XORed with 7: `flip`), so inside a block every walk moves up by the axis' unit (1, 8,
/// 64) and leaves the block where that mirrored coordinate is 7, adding the lane's crossing
/// increment for the axis instead (its block stride, signed, less 7 units). An axis no walk
/// moves along (delta 0) is never chosen (its crossing time is the largest double).
struct FourPlaces {
  __m256i addr, flip, c0, c1, c2;  // addr ^ flip: the voxel's address; cA: crossing less a unit
  /// Puts walk place `at` in the lane(s) `k` holds.
  [[DENSEMAP_AVX2, gnu::always_inline]] void load(__m256i k, const DenseMarks::WalkPlace& at) {
    long long f = 0;
    long long c[3];
    for (int a = 0; a < 3; ++a) {
      const long long unit = 1LL << (block::kShift * a);
      if (at.small[a] < 0) f |= (block::kEdge - 1) * unit;
      // wrap + (kEdge - 1) small: the block stride signed (see DenseMarks::place).
      c[a] = at.wrap[a] + (block::kEdge - 1) * static_cast<long long>(at.small[a]) -
             block::kEdge * unit;
    }
    putLanes(addr, static_cast<long long>(at.addr) ^ f, k);
    putLanes(flip, f, k);
    putLanes(c0, c[0], k);
    putLanes(c1, c[1], k);
    putLanes(c2, c[2], k);
  }
  /// The lanes in m0 / m1 / m2 step along axis 0 / 1 / 2.
  [[DENSEMAP_AVX2, gnu::always_inline]] void move(__m256i m0, __m256i m1, __m256i m2) {
    __m256i inc = _mm256_and_si256(m0, _mm256_set1_epi64x(1));
    inc = _mm256_or_si256(inc, _mm256_and_si256(m1, _mm256_set1_epi64x(block::kEdge)));
    inc =
        _mm256_or_si256(inc, _mm256_and_si256(m2, _mm256_set1_epi64x(block::kEdge * block::kEdge)));
    // The moving axis' 3 bits (7 units), all set at the block's border.
    const __m256i field = _mm256_sub_epi64(_mm256_slli_epi64(inc, block::kShift), inc);
    __m256i cross = _mm256_and_si256(m0, c0);
    cross = _mm256_or_si256(cross, _mm256_and_si256(m1, c1));
    cross = _mm256_or_si256(cross, _mm256_and_si256(m2, c2));
    const __m256i border = _mm256_cmpeq_epi64(_mm256_and_si256(addr, field), field);
    addr = _mm256_add_epi64(addr, _mm256_add_epi64(inc, _mm256_and_si256(border, cross)));
  }
  /// The lanes' voxel addresses (block * kVoxels + block::indexOf).
  [[DENSEMAP_AVX2, gnu::always_inline]] __m256i voxel() const {
    return _mm256_xor_si256(addr, flip);
  }
};

/// The forward walks' steps four at a time in AVX2 lanes, as walkEight: the same choice (the
/// smallest tMax, ties to the higher axis) from the same double additions, a lane taking the
/// next walk when its own is done, marks gathered per lane and word and pended when the lane
/// moves on. No blocks entered are listed (finishPended takes them from the pended words: per
/// step that was 9 of some 70 instructions). `out` must have room for (all the walks' steps + 1)
/// + 16.
[[DENSEMAP_AVX2]] void walkFour(const DenseMarks::QueuedWalk* walks, std::size_t n, WideOut& out) {
  const __m256i one = _mm256_set1_epi64x(1), zero = _mm256_setzero_si256(),
                low6 = _mm256_set1_epi64x(63);
  __m256d t0 = _mm256_setzero_pd(), t1 = t0, t2 = t0, d0 = t0, d1 = t0, d2 = t0;
  FourPlaces p{zero, zero, zero, zero, zero};
  __m256i left = zero;                 // the lane's steps to go
  __m256i cur_w = zero, cur_b = zero;  // the word being marked, its marks so far
  int live = 0;                        // lanes with a walk whose last marks are not pended
  std::size_t next = 0;
  // The outputs' ends in locals: stores through the uint64_t pointers could alias `out`'s
  // counters, which would keep them in memory (a store-to-load round trip every step).
  std::uint64_t* pend_w = out.pend_w + out.n_pend;
  std::uint64_t* pend_b = out.pend_b + out.n_pend;
  while (true) {
    __m256i active = _mm256_cmpgt_epi64(left, zero);
    int act = bitsOf(active);
    if (act != 0xf) {
      const int done = live & ~act;
      pendFour(done, cur_w, cur_b, pend_w, pend_b);
      cur_b = _mm256_and_si256(cur_b, active);
      // Idle lanes take the next walks.
      for (unsigned idle = ~static_cast<unsigned>(act) & 0xfU; idle != 0 && next < n;
           idle &= idle - 1, ++next) {
        const DenseMarks::QueuedWalk& w = walks[next];
        const __m256i k =
            _mm256_load_si256(reinterpret_cast<const __m256i*>(kFour.lane[std::countr_zero(idle)]));
        const __m256d kd = _mm256_castsi256_pd(k);
        t0 = _mm256_blendv_pd(t0, _mm256_set1_pd(w.t_max[0]), kd);
        t1 = _mm256_blendv_pd(t1, _mm256_set1_pd(w.t_max[1]), kd);
        t2 = _mm256_blendv_pd(t2, _mm256_set1_pd(w.t_max[2]), kd);
        d0 = _mm256_blendv_pd(d0, _mm256_set1_pd(w.t_delta[0]), kd);
        d1 = _mm256_blendv_pd(d1, _mm256_set1_pd(w.t_delta[1]), kd);
        d2 = _mm256_blendv_pd(d2, _mm256_set1_pd(w.t_delta[2]), kd);
        p.load(k, w.at);
        putLanes(left, w.steps, k);
        putLanes(cur_w, static_cast<long long>(w.at.addr >> 6), k);
      }
      active = _mm256_cmpgt_epi64(left, zero);
      act = bitsOf(active);
      live = act;
      if (act == 0) break;
    }
    left = _mm256_add_epi64(left, active);  // active lanes are -1
    const __m256i lt01 = _mm256_castpd_si256(_mm256_cmp_pd(t0, t1, _CMP_LT_OQ));
    const __m256i lt02 = _mm256_castpd_si256(_mm256_cmp_pd(t0, t2, _CMP_LT_OQ));
    const __m256i lt12 = _mm256_castpd_si256(_mm256_cmp_pd(t1, t2, _CMP_LT_OQ));
    const __m256i m0 = _mm256_and_si256(active, _mm256_and_si256(lt01, lt02));
    const __m256i m1 = _mm256_and_si256(active, _mm256_andnot_si256(lt01, lt12));
    const __m256i m2 = _mm256_andnot_si256(_mm256_or_si256(m0, m1), active);
    t0 = _mm256_blendv_pd(t0, _mm256_add_pd(t0, d0), _mm256_castsi256_pd(m0));
    t1 = _mm256_blendv_pd(t1, _mm256_add_pd(t1, d1), _mm256_castsi256_pd(m1));
    t2 = _mm256_blendv_pd(t2, _mm256_add_pd(t2, d2), _mm256_castsi256_pd(m2));
    p.move(m0, m1, m2);
    const __m256i voxel = p.voxel();
    const __m256i word = _mm256_srli_epi64(voxel, 6);
    const __m256i moved = _mm256_andnot_si256(_mm256_cmpeq_epi64(word, cur_w), active);
    pendFour(bitsOf(moved), cur_w, cur_b, pend_w, pend_b);
    cur_w = _mm256_blendv_epi8(cur_w, word, moved);
    cur_b = _mm256_andnot_si256(moved, cur_b);
    cur_b = _mm256_or_si256(
        cur_b, _mm256_and_si256(active, _mm256_sllv_epi64(one, _mm256_and_si256(voxel, low6))));
  }
  out.n_pend = static_cast<std::size_t>(pend_w - out.pend_w);
}

/// The 32-bit lanes a mask names, packed to the front (a permute's indices), per 8-bit mask.
/// And per lane, all-ones in the 32-bit lanes but that one.
struct EightLaneTable {
  alignas(32) std::int32_t pack32[256][8];
  alignas(32) std::int32_t others[8][8];
};
constexpr EightLaneTable makeEightLaneTable() {
  EightLaneTable t{};
  for (int m = 0; m < 256; ++m) {
    int n = 0;
    for (int i = 0; i < 8; ++i) {
      if ((m >> i & 1) != 0) t.pack32[m][n++] = i;
    }
  }
  for (int lane = 0; lane < 8; ++lane) {
    for (int i = 0; i < 8; ++i) t.others[lane][i] = i == lane ? 0 : -1;
  }
  return t;
}
constexpr EightLaneTable kEight = makeEightLaneTable();

/// Pends the 32-bit words and marks of the lanes `bits` names (packed at the pointers, which
/// move on; 8 slots written).
[[DENSEMAP_AVX2, gnu::always_inline]] inline void pendEight(unsigned bits, __m256i words,
                                                            __m256i marks, std::uint32_t*& pend_w,
                                                            std::uint32_t*& pend_b) {
  const __m256i idx = _mm256_load_si256(reinterpret_cast<const __m256i*>(kEight.pack32[bits]));
  _mm256_storeu_si256(reinterpret_cast<__m256i*>(pend_w), _mm256_permutevar8x32_epi32(words, idx));
  _mm256_storeu_si256(reinterpret_cast<__m256i*>(pend_b), _mm256_permutevar8x32_epi32(marks, idx));
  const auto pended = static_cast<std::size_t>(std::popcount(bits));
  pend_w += pended;
  pend_b += pended;
}
/// All-ones in the 32-bit lanes `bits` names.
[[DENSEMAP_AVX2, gnu::always_inline]] inline __m256i lanesOf(unsigned bits) {
  const __m256i each = _mm256_setr_epi32(1, 2, 4, 8, 16, 32, 64, 128);
  return _mm256_cmpeq_epi32(_mm256_and_si256(_mm256_set1_epi32(static_cast<int>(bits)), each),
                            each);
}
/// `x` into the 32-bit lanes `k` holds.
[[DENSEMAP_AVX2, gnu::always_inline]] inline void putLanes32(__m256i& v, __m256i k,
                                                             std::int32_t x) {
  v = _mm256_blendv_epi8(v, _mm256_set1_epi32(x), k);
}
/// The 32-bit lanes a vector mask holds, as bits.
[[DENSEMAP_AVX2, gnu::always_inline]] inline unsigned bitsOf32(__m256i m) {
  return static_cast<unsigned>(_mm256_movemask_ps(_mm256_castsi256_ps(m)));
}

/// The forward walks' steps eight at a time in AVX2 lanes of 32-bit fixed-point times
/// (DenseMarks::FixedWalk): walkFour's walks, a lane taking the next walk when its own is done,
/// with countedSteps' choice (the smallest time) made from integers that are each within
/// (k + 1) / 2 + 2^-10 units of the double time after k additions (the rounding of the start
/// and of each delta, 1/2 unit each, and the doubles' own error): a step is taken only when
/// the smallest time is below the others by more than the walk's slack (steps / 2 + 3, above
/// two such errors), so the doubles' decision, ties included, is the same one. A lane whose
/// decision is closer than that stops, unstepped, and its walk's queue index is appended at
/// `handed_over` + `n_handed` (room for n; what it marked is part of the walk's marks). Marks are
/// gathered per 32-bit word and pended when the lane moves on. `pend_w` / `pend_b` need room for
/// (all the walks' steps + 1) + 16.
[[DENSEMAP_AVX2]] std::size_t walkEightFixed(const DenseMarks::FixedWalk* walks, std::size_t n,
                                             std::uint32_t* pend_w, std::uint32_t* pend_b,
                                             std::uint32_t* handed_over, std::size_t& n_handed) {
  // The lanes' state that no step changes, and the constants, in memory: the step's assembly
  // reads them as memory operands, which leaves the 16 registers to the state a step changes
  // (7 vectors) and its temporaries. (GCC, given the intrinsics, held these in registers, built
  // the constants from immediates, three instructions each, and spilled the changing state.)
  enum : int { kD0, kD1, kD2, kSlack, kFlip, kC0, kC1, kC2, kOne, kEdge, kEdge2, kLow5, kMinus2 };
  alignas(32) __m256i ro[13];  // (the assembly below reads them at 32 * index)
  static_assert(kD1 == 1 && kD2 == 2 && kSlack == 3 && kFlip == 4 && kC0 == 5 && kC1 == 6 &&
                kC2 == 7 && kOne == 8 && kEdge == 9 && kEdge2 == 10 && kLow5 == 11 &&
                kMinus2 == 12 && sizeof(__m256i) == 32);
  using Walk = DenseMarks::FixedWalk;  // (the refill's assembly reads its fields at these)
  static_assert(offsetof(Walk, t) == 0 && offsetof(Walk, d) == 12 && offsetof(Walk, slack) == 24 &&
                offsetof(Walk, steps) == 28 && offsetof(Walk, addr) == 32 &&
                offsetof(Walk, flip) == 36 && offsetof(Walk, cross) == 40);
  const __m256i zero = _mm256_setzero_si256();
  // A lane without a walk has this slack: every time is above its threshold (no step, no
  // hand-over).
  const __m256i no_walk = _mm256_set1_epi32(-(1 << 30));
  for (__m256i& v : ro) v = zero;
  ro[kSlack] = no_walk;
  ro[kOne] = _mm256_set1_epi32(1);
  ro[kEdge] = _mm256_set1_epi32(block::kEdge);
  ro[kEdge2] = _mm256_set1_epi32(block::kEdge * block::kEdge);
  ro[kLow5] = _mm256_set1_epi32(31);
  ro[kMinus2] = _mm256_set1_epi32(-2);
  __m256i t0 = zero, t1 = zero, t2 = zero, addr = zero;
  __m256i left = zero;                 // the lane's steps to go
  __m256i cur_w = zero, cur_b = zero;  // the 32-bit word of the lane's voxel, its marks so far
  unsigned live = 0;                   // lanes with a walk whose last marks are not pended
  std::uint32_t lane_walk[8] = {0, 0, 0, 0, 0, 0, 0, 0};
  std::uint32_t* const pend_start = pend_w;
  std::size_t next = 0;
  while (true) {
    const __m256i active = _mm256_cmpgt_epi32(left, zero);
    unsigned act = bitsOf32(active);
    if (act != 0xffU) {
      pendEight(live & ~act, cur_w, cur_b, pend_w, pend_b);
      cur_b = _mm256_and_si256(cur_b, active);
      ro[kSlack] = _mm256_blendv_epi8(no_walk, ro[kSlack], active);
      // Idle lanes take the next walks.
      // (In assembly: written with the intrinsics, GCC moved the read-only vectors out of
      // `ro` into other stack slots and registers around this loop and back after it, some 150
      // instructions a walk; this is some 60.)
      for (unsigned idle = ~act & 0xffU; idle != 0 && next < n; idle &= idle - 1, ++next) {
        const DenseMarks::FixedWalk& w = walks[next];
        const int lane = std::countr_zero(idle);
        lane_walk[lane] = w.index;
        const std::int32_t word = (w.addr ^ w.flip) >> 5;
        __m256i x, k;
        // Each field broadcast, and taken in `lane` (the others keep theirs: `others`' lanes).
        asm("vmovdqa (%[others]), %t[k]\n\t"
            "vpbroadcastd 0(%[w]), %t[x]\n\t"
            "vpblendvb %t[k], %t[t0], %t[x], %t[t0]\n\t"
            "vpbroadcastd 4(%[w]), %t[x]\n\t"
            "vpblendvb %t[k], %t[t1], %t[x], %t[t1]\n\t"
            "vpbroadcastd 8(%[w]), %t[x]\n\t"
            "vpblendvb %t[k], %t[t2], %t[x], %t[t2]\n\t"
            "vpbroadcastd 28(%[w]), %t[x]\n\t"
            "vpblendvb %t[k], %t[left], %t[x], %t[left]\n\t"
            "vpbroadcastd 32(%[w]), %t[x]\n\t"
            "vpblendvb %t[k], %t[addr], %t[x], %t[addr]\n\t"
            "vmovd %[word], %x[x]\n\t"
            "vpbroadcastd %x[x], %t[x]\n\t"
            "vpblendvb %t[k], %t[cur_w], %t[x], %t[cur_w]\n\t"
            // d0, d1, d2 (ro 0-2), slack (3), flip (4), the crossings (5-7)
            "vpbroadcastd 12(%[w]), %t[x]\n\t"
            "vpblendvb %t[k], 0(%[ro]), %t[x], %t[x]\n\t"
            "vmovdqa %t[x], 0(%[ro])\n\t"
            "vpbroadcastd 16(%[w]), %t[x]\n\t"
            "vpblendvb %t[k], 32(%[ro]), %t[x], %t[x]\n\t"
            "vmovdqa %t[x], 32(%[ro])\n\t"
            "vpbroadcastd 20(%[w]), %t[x]\n\t"
            "vpblendvb %t[k], 64(%[ro]), %t[x], %t[x]\n\t"
            "vmovdqa %t[x], 64(%[ro])\n\t"
            "vpbroadcastd 24(%[w]), %t[x]\n\t"
            "vpblendvb %t[k], 96(%[ro]), %t[x], %t[x]\n\t"
            "vmovdqa %t[x], 96(%[ro])\n\t"
            "vpbroadcastd 36(%[w]), %t[x]\n\t"
            "vpblendvb %t[k], 128(%[ro]), %t[x], %t[x]\n\t"
            "vmovdqa %t[x], 128(%[ro])\n\t"
            "vpbroadcastd 40(%[w]), %t[x]\n\t"
            "vpblendvb %t[k], 160(%[ro]), %t[x], %t[x]\n\t"
            "vmovdqa %t[x], 160(%[ro])\n\t"
            "vpbroadcastd 44(%[w]), %t[x]\n\t"
            "vpblendvb %t[k], 192(%[ro]), %t[x], %t[x]\n\t"
            "vmovdqa %t[x], 192(%[ro])\n\t"
            "vpbroadcastd 48(%[w]), %t[x]\n\t"
            "vpblendvb %t[k], 224(%[ro]), %t[x], %t[x]\n\t"
            "vmovdqa %t[x], 224(%[ro])"
            : [t0] "+x"(t0), [t1] "+x"(t1), [t2] "+x"(t2), [left] "+x"(left), [addr] "+x"(addr),
              [cur_w] "+x"(cur_w), [x] "=&x"(x), [k] "=&x"(k),
              "+m"(*reinterpret_cast<__m256i(*)[13]>(ro))
            : [w] "r"(&w), [ro] "r"(ro), [others] "r"(kEight.others[lane]), [word] "r"(word),
              "m"(w), "m"(kEight.others[lane]));
        act |= 1U << lane;
      }
      live = act;
      if (act == 0) break;
    }
    // The smallest time; the axes above it by more than the slack (n_a) do not step. Exactly
    // one axis within the slack: n0 + n1 + n2 == -2; with more, the decision is too close to
    // call: the lane stops (its slack no_walk's: no axis within) and its walk is handed over.
    // (In assembly, this and the step below: with the intrinsics, GCC's registers spilled the
    // state a step changes, some 82 instructions a step where the loop now takes 65.)
    __m256i n0, n1, n2;
    while (true) {
      __m256i thr;
      std::uint64_t unsure;
      asm("vpminsd %t[t1], %t[t0], %t[thr]\n\t"
          "vpminsd %t[t2], %t[thr], %t[thr]\n\t"
          "vpaddd 96(%[ro]), %t[thr], %t[thr]\n\t"
          "vpcmpgtd %t[thr], %t[t0], %t[n0]\n\t"
          "vpcmpgtd %t[thr], %t[t1], %t[n1]\n\t"
          "vpcmpgtd %t[thr], %t[t2], %t[n2]\n\t"
          "vpaddd %t[n1], %t[n0], %t[thr]\n\t"
          "vpaddd %t[n2], %t[thr], %t[thr]\n\t"
          "vpcmpgtd 384(%[ro]), %t[thr], %t[thr]\n\t"
          "vmovmskps %t[thr], %k[unsure]"
          : [n0] "=&x"(n0), [n1] "=&x"(n1), [n2] "=&x"(n2), [thr] "=&x"(thr), [unsure] "=r"(unsure)
          : [t0] "x"(t0), [t1] "x"(t1), [t2] "x"(t2), [ro] "r"(ro),
            "m"(*reinterpret_cast<const __m256i(*)[13]>(ro)));
      if (unsure == 0) [[likely]]
        break;
      // (No call here: it would make GCC keep the lanes' state in memory on the common path.)
      for (unsigned u = unsure; u != 0; u &= u - 1) {
        handed_over[n_handed++] = lane_walk[std::countr_zero(u)];
      }
      const __m256i stop = lanesOf(unsure);
      ro[kSlack] = _mm256_blendv_epi8(ro[kSlack], no_walk, stop);
      left = _mm256_andnot_si256(stop, left);  // done after this (unstepped) step
    }
    // The step: the times of the axes stepped on, the places (FourPlaces::move in 32 bits, the
    // masks negated), the voxel's word and mark (lanes that did not step stay on their word),
    // the marks of the lanes that moved to another word pended (pendEight), a step less to go.
    __m256i x1, x2, x3, x4;
    std::uint64_t moved, pended;
    asm("vpandn 0(%[ro]), %t[n0], %t[x1]\n\t"
        "vpaddd %t[x1], %t[t0], %t[t0]\n\t"
        "vpandn 32(%[ro]), %t[n1], %t[x1]\n\t"
        "vpaddd %t[x1], %t[t1], %t[t1]\n\t"
        "vpandn 64(%[ro]), %t[n2], %t[x1]\n\t"
        "vpaddd %t[x1], %t[t2], %t[t2]\n\t"
        // x1: the unit moved by (inc); x2: the block crossing's increment less the unit
        "vpandn 256(%[ro]), %t[n0], %t[x1]\n\t"
        "vpandn 288(%[ro]), %t[n1], %t[x3]\n\t"
        "vpor %t[x3], %t[x1], %t[x1]\n\t"
        "vpandn 320(%[ro]), %t[n2], %t[x3]\n\t"
        "vpor %t[x3], %t[x1], %t[x1]\n\t"
        "vpandn 160(%[ro]), %t[n0], %t[x2]\n\t"
        "vpandn 192(%[ro]), %t[n1], %t[x3]\n\t"
        "vpor %t[x3], %t[x2], %t[x2]\n\t"
        "vpandn 224(%[ro]), %t[n2], %t[x3]\n\t"
        "vpor %t[x3], %t[x2], %t[x2]\n\t"
        // x3: the moving axis' field (7 units); x4: at the block's border
        "vpslld $3, %t[x1], %t[x3]\n\t"
        "vpsubd %t[x1], %t[x3], %t[x3]\n\t"
        "vpand %t[x3], %t[addr], %t[x4]\n\t"
        "vpcmpeqd %t[x3], %t[x4], %t[x4]\n\t"
        "vpand %t[x4], %t[x2], %t[x2]\n\t"
        "vpaddd %t[x1], %t[addr], %t[addr]\n\t"
        "vpaddd %t[x2], %t[addr], %t[addr]\n\t"
        // x1: the voxel; x2: its word; x3: on the same word as before
        "vpxor 128(%[ro]), %t[addr], %t[x1]\n\t"
        "vpsrld $5, %t[x1], %t[x2]\n\t"
        "vpcmpeqd %t[cur_w], %t[x2], %t[x3]\n\t"
        "vmovmskps %t[x3], %k[moved]\n\t"
        "xorl $0xff, %k[moved]\n\t"
        "movq %[moved], %[pended]\n\t"
        "shlq $5, %[pended]\n\t"
        "vmovdqa (%[pack], %[pended]), %t[x4]\n\t"
        "popcntq %[moved], %[pended]\n\t"
        "vpermd %t[cur_w], %t[x4], %t[cur_w]\n\t"
        "vmovdqu %t[cur_w], (%[pw])\n\t"
        "vpermd %t[cur_b], %t[x4], %t[x4]\n\t"
        "vmovdqu %t[x4], (%[pb])\n\t"
        "leaq (%[pw], %[pended], 4), %[pw]\n\t"
        "leaq (%[pb], %[pended], 4), %[pb]\n\t"
        "vmovdqa %t[x2], %t[cur_w]\n\t"
        "vpand %t[x3], %t[cur_b], %t[cur_b]\n\t"
        "vpand 352(%[ro]), %t[x1], %t[x1]\n\t"
        "vmovdqa 256(%[ro]), %t[x4]\n\t"
        "vpsllvd %t[x1], %t[x4], %t[x4]\n\t"
        "vpor %t[x4], %t[cur_b], %t[cur_b]\n\t"
        "vpsubd 256(%[ro]), %t[left], %t[left]"
        : [left] "+x"(left), [t0] "+x"(t0), [t1] "+x"(t1), [t2] "+x"(t2), [addr] "+x"(addr),
          [cur_w] "+x"(cur_w), [cur_b] "+x"(cur_b), [pw] "+r"(pend_w), [pb] "+r"(pend_b),
          [x1] "=&x"(x1), [x2] "=&x"(x2), [x3] "=&x"(x3), [x4] "=&x"(x4), [moved] "=&r"(moved),
          [pended] "=&r"(pended)
        : [n0] "x"(n0), [n1] "x"(n1), [n2] "x"(n2), [ro] "r"(ro), [pack] "r"(kEight.pack32)
        : "memory");
  }
  return static_cast<std::size_t>(pend_w - pend_start);
}

#define DENSEMAP_AVX512_FIXED gnu::target("avx512f,avx512vl,avx512dq,popcnt,bmi2")

/// Pends the 32-bit words and marks of the 16 lanes `lanes` names (packed at the pointers,
/// which move on; 16 slots written).
[[DENSEMAP_AVX512_FIXED, gnu::always_inline]] inline void pendSixteen(__mmask16 lanes,
                                                                      __m512i words, __m512i marks,
                                                                      std::uint32_t*& pend_w,
                                                                      std::uint32_t*& pend_b) {
  // (Compressed in a register, then stored: a compressing store is microcoded on AMD's cores.)
  _mm512_storeu_si512(pend_w, _mm512_maskz_compress_epi32(lanes, words));
  _mm512_storeu_si512(pend_b, _mm512_maskz_compress_epi32(lanes, marks));
  const auto pended = static_cast<std::size_t>(std::popcount(static_cast<unsigned>(lanes)));
  pend_w += pended;
  pend_b += pended;
}

/// FixedWalk's 14 fields (t[3], d[3], slack, steps, addr, flip, cross[3], index: 32 bits each)
/// as 14 rows of `stride` (n + 16 or more), walk i's in column i: the layout walkSixteenFixed
/// refills its lanes from.
constexpr int kFixedFields = 14;
static_assert(sizeof(DenseMarks::FixedWalk) == kFixedFields * sizeof(std::int32_t));
void fixedColumns(const DenseMarks::FixedWalk* walks, std::size_t n, std::size_t stride,
                  std::int32_t* rows) {
  for (std::size_t i = 0; i < n; ++i) {
    std::int32_t f[kFixedFields];
    std::memcpy(f, &walks[i], sizeof f);
#pragma GCC unroll 14
    for (int k = 0; k < kFixedFields; ++k) rows[k * stride + i] = f[k];
  }
}

/// `walks` (n of them) as fixedColumns' rows in `rows` (grown when short); returns the stride.
std::size_t fixedColumnsInto(const DenseMarks::FixedWalk* walks, std::size_t n,
                             std::vector<std::int32_t>& rows) {
  const std::size_t stride = n + 16;
  if (rows.size() < kFixedFields * stride) {
    rows.resize(std::max<std::size_t>(kFixedFields * stride, 2 * rows.size()));
  }
  fixedColumns(walks, n, stride, rows.data());
  return stride;
}

/// walkSixteenFixed refills its lanes once this many are idle: fewer refills, each of several
/// lanes (a refill's branch mispredicts). 4 is the fastest of 2, 4, 6 and 8 on a Zen 5 (BALM
/// 0.2 m), and faster than refilling each lane as its walk ends (as walkEightFixed does).
constexpr unsigned kSixteenRefillAt = 4;

/// Sixteen walks' FixedWalk fields, a lane each (`t`: the forward walks' times or the backward
/// walks' heads; `ids`: their index fields).
struct SixteenWalks {
  __m512i t0, t1, t2, d0, d1, d2, slack, left, addr, flip, c0, c1, c2, ids;
  /// The lanes `fill` names take the next walks, in lane order: each field's values at `at`
  /// (fixedColumns' rows, `stride` apart) expanded into them.
  [[DENSEMAP_AVX512_FIXED, gnu::always_inline]] void refill(__mmask16 fill, const std::int32_t* at,
                                                            std::size_t stride) {
    __m512i* const fields[kFixedFields] = {&t0,    &t1,   &t2,   &d0,   &d1, &d2, &slack,
                                           &left,  &addr, &flip, &c0,   &c1, &c2, &ids};
#pragma GCC unroll 14
    for (int f = 0; f < kFixedFields; ++f) {
      *fields[f] = _mm512_mask_expand_epi32(*fields[f], fill, _mm512_loadu_si512(at + f * stride));
    }
  }
  /// The lanes in m0 / m1 / m2 step along axis 0 / 1 / 2 (FourPlaces::move in 32 bits: the unit
  /// moved by, plus the axis' crossing increment where the lane was at its block's border);
  /// returns the lanes' voxels.
  [[DENSEMAP_AVX512_FIXED, gnu::always_inline]] __m512i move(__mmask16 m0, __mmask16 m1,
                                                             __mmask16 m2) {
    __m512i inc = _mm512_maskz_mov_epi32(m0, _mm512_set1_epi32(1));
    inc = _mm512_mask_mov_epi32(inc, m1, _mm512_set1_epi32(block::kEdge));
    inc = _mm512_mask_mov_epi32(inc, m2, _mm512_set1_epi32(block::kEdge * block::kEdge));
    __m512i cross = _mm512_maskz_mov_epi32(m0, c0);
    cross = _mm512_mask_mov_epi32(cross, m1, c1);
    cross = _mm512_mask_mov_epi32(cross, m2, c2);
    const __m512i field = _mm512_sub_epi32(_mm512_slli_epi32(inc, block::kShift), inc);
    const __mmask16 border = _mm512_cmpeq_epi32_mask(_mm512_and_si512(addr, field), field);
    addr = _mm512_add_epi32(addr, inc);
    addr = _mm512_mask_add_epi32(addr, border, addr, cross);
    return _mm512_xor_si512(addr, flip);
  }
};

/// walkEightFixed's walks sixteen at a time in AVX-512 lanes of 32-bit fixed-point times: the
/// same integers, the same decisions (a step only when the smallest time is below the others by
/// more than the slack, else the walk is handed over), the same marks pended per 32-bit word.
/// The decision's axes are mask registers, and with 32 vector registers all the lanes' state
/// stays in registers. A lane whose walk is done waits, masked off, until kSixteenRefillAt
/// lanes are (or the queue is out): then they take the next walks at once, each field expanded
/// into them from `rows` (fixedColumns' of these walks, `stride` apart; no loop over the
/// lanes, whose count would mispredict). Same contract as walkEightFixed; `pend_w` / `pend_b`
/// need room for (all the walks' steps + 1) + 16.
[[DENSEMAP_AVX512_FIXED]] std::size_t walkSixteenFixed(const std::int32_t* rows, std::size_t stride,
                                                       std::size_t n, std::uint32_t* pend_w,
                                                       std::uint32_t* pend_b,
                                                       std::uint32_t* handed_over,
                                                       std::size_t& n_handed) {
  const __m512i zero = _mm512_setzero_si512(), one = _mm512_set1_epi32(1),
                low5 = _mm512_set1_epi32(31);
  SixteenWalks w{zero, zero, zero, zero, zero, zero, zero,
                 zero, zero, zero, zero, zero, zero, zero};
  __m512i cur_w = zero, cur_b = zero;  // the 32-bit word of the lane's voxel, its marks so far
  __mmask16 live = 0;                  // lanes with a walk whose last marks are not pended
  std::uint32_t* const pend_start = pend_w;
  std::size_t next = 0;
  unsigned refill_at = kSixteenRefillAt;
  while (true) {
    __mmask16 act = _mm512_cmpgt_epi32_mask(w.left, zero);
    const unsigned idle = ~static_cast<unsigned>(act) & 0xffffU;
    if (static_cast<unsigned>(std::popcount(idle)) >= refill_at) [[unlikely]] {
      pendSixteen(static_cast<__mmask16>(live & idle), cur_w, cur_b, pend_w, pend_b);
      const auto take = static_cast<unsigned>(
          std::min<std::size_t>(static_cast<std::size_t>(std::popcount(idle)), n - next));
      const auto fill = static_cast<__mmask16>(_pdep_u32((1U << take) - 1U, idle));
      w.refill(fill, rows + next, stride);
      cur_w = _mm512_mask_srli_epi32(cur_w, fill, _mm512_xor_si512(w.addr, w.flip), 5);
      cur_b = _mm512_maskz_mov_epi32(act, cur_b);
      next += take;
      act = static_cast<__mmask16>(act | fill);
      live = act;
      if (next == n) refill_at = 1;  // (then every lane pended as soon as it is done)
      if (act == 0) break;
    }
    // The axes within the slack of the smallest time step; a lane with more than one is too
    // close to call: it stops, unstepped, and its walk is handed over (walkEightFixed's rule).
    // Lanes without a walk (or done) are masked off: no step.
    const __m512i thr =
        _mm512_add_epi32(_mm512_min_epi32(_mm512_min_epi32(w.t0, w.t1), w.t2), w.slack);
    __mmask16 k0 = _mm512_mask_cmple_epi32_mask(act, w.t0, thr);
    __mmask16 k1 = _mm512_mask_cmple_epi32_mask(act, w.t1, thr);
    __mmask16 k2 = _mm512_mask_cmple_epi32_mask(act, w.t2, thr);
    const auto unsure = static_cast<__mmask16>((k0 & k1) | (k0 & k2) | (k1 & k2));
    if (unsure != 0) [[unlikely]] {
      alignas(64) std::uint32_t lane_walk[16];
      _mm512_store_si512(lane_walk, w.ids);
      for (unsigned u = unsure; u != 0; u &= u - 1) {
        handed_over[n_handed++] = lane_walk[std::countr_zero(u)];
      }
      w.left = _mm512_maskz_mov_epi32(static_cast<__mmask16>(~unsure), w.left);  // done after
      k0 = static_cast<__mmask16>(k0 & ~unsure);
      k1 = static_cast<__mmask16>(k1 & ~unsure);
      k2 = static_cast<__mmask16>(k2 & ~unsure);
    }
    // The step: the times of the axes stepped on, the place, the voxel's word and mark, the
    // marks of the lanes that moved to another word pended.
    w.t0 = _mm512_mask_add_epi32(w.t0, k0, w.t0, w.d0);
    w.t1 = _mm512_mask_add_epi32(w.t1, k1, w.t1, w.d1);
    w.t2 = _mm512_mask_add_epi32(w.t2, k2, w.t2, w.d2);
    const __m512i voxel = w.move(k0, k1, k2);
    const __m512i word = _mm512_srli_epi32(voxel, 5);
    const __mmask16 moved = _mm512_cmpneq_epi32_mask(word, cur_w);
    pendSixteen(moved, cur_w, cur_b, pend_w, pend_b);
    cur_w = word;
    cur_b = _mm512_maskz_mov_epi32(static_cast<__mmask16>(~moved), cur_b);
    cur_b = _mm512_or_si512(cur_b, _mm512_sllv_epi32(one, _mm512_and_si512(voxel, low5)));
    w.left = _mm512_sub_epi32(w.left, one);
  }
  return static_cast<std::size_t>(pend_w - pend_start);
}

/// walkEightFixedBack's walks sixteen at a time in AVX-512 lanes: the same integers and
/// decisions (the latest head winning by more than the slack, else the walk is handed over), the
/// region's word gathered when a lane moves to another word and the voxel tested (and marked)
/// one iteration later, the marks pended per 32-bit word; lanes refilled as walkSixteenFixed's,
/// from the walks field by field (`rows`, `stride`). Same contract as walkEightFixedBack.
[[DENSEMAP_AVX512_FIXED]] DenseMarks::BackWalkCounts walkSixteenFixedBack(
    const std::int32_t* rows, std::size_t stride, std::size_t n, const std::uint32_t* culled,
    std::uint32_t* pend_w, std::uint32_t* pend_b, std::uint32_t* handed_over,
    std::size_t& n_handed, std::size_t& n_pend) {
  const __m512i zero = _mm512_setzero_si512(), one = _mm512_set1_epi32(1),
                low5 = _mm512_set1_epi32(31);
  SixteenWalks w{zero, zero, zero, zero, zero, zero, zero,  // (w.t: the heads)
                 zero, zero, zero, zero, zero, zero, zero};
  __m512i total = zero, marked = zero;  // steps in all; voxels marked
  // cur_w: the 32-bit word of the lane's voxel; cur_b: the marks so far in it; cur_r: the
  // region's bits of it; pending: the bit of the voxel moved to and not yet tested (0: none).
  __m512i cur_w = zero, cur_b = zero, cur_r = zero, pending = zero;
  __mmask16 live = 0, handing = 0;
  std::uint32_t* const pend_start = pend_w;
  DenseMarks::BackWalkCounts counts;
  std::size_t next = 0;
  unsigned refill_at = kSixteenRefillAt;
  while (true) {
    __mmask16 active = _mm512_cmpgt_epi32_mask(w.left, zero);
    const __mmask16 tested = _mm512_test_epi32_mask(pending, pending);
    const auto busy = static_cast<__mmask16>(active | tested);
    const unsigned idle = ~static_cast<unsigned>(busy) & 0xffffU;
    if (static_cast<unsigned>(std::popcount(idle)) >= refill_at) [[unlikely]] {
      // The walks done: their marks pended, their counts added (or handed over).
      const auto done = static_cast<__mmask16>(live & idle);
      pendSixteen(done, cur_w, cur_b, pend_w, pend_b);
      const auto counted = static_cast<__mmask16>(done & ~handing);
      counts.visits += static_cast<std::uint32_t>(_mm512_mask_reduce_add_epi32(counted, marked));
      counts.culled += static_cast<std::uint32_t>(
          _mm512_mask_reduce_add_epi32(counted, _mm512_sub_epi32(total, marked)));
      if (const auto handed = static_cast<unsigned>(done & handing); handed != 0) {
        alignas(64) std::uint32_t lane_walk[16];
        _mm512_store_si512(lane_walk, w.ids);
        for (unsigned u = handed; u != 0; u &= u - 1) {
          handed_over[n_handed++] = lane_walk[std::countr_zero(u)];
        }
      }
      handing = static_cast<__mmask16>(handing & ~done);
      cur_b = _mm512_maskz_mov_epi32(busy, cur_b);
      marked = _mm512_maskz_mov_epi32(busy, marked);
      const auto take = static_cast<unsigned>(
          std::min<std::size_t>(static_cast<std::size_t>(std::popcount(idle)), n - next));
      const auto fill = static_cast<__mmask16>(_pdep_u32((1U << take) - 1U, idle));
      w.refill(fill, rows + next, stride);
      total = _mm512_mask_mov_epi32(total, fill, w.left);
      cur_w = _mm512_mask_srli_epi32(cur_w, fill, _mm512_xor_si512(w.addr, w.flip), 5);
      cur_r = _mm512_mask_i32gather_epi32(cur_r, fill, cur_w, culled, 4);
      next += take;
      live = static_cast<__mmask16>(busy | fill);
      if (next == n) refill_at = 1;  // (then every lane counted as soon as it is done)
      if (live == 0) break;
      active = _mm512_cmpgt_epi32_mask(w.left, zero);
    }
    // The latest head; the axes within the slack of it (w_a) step; exactly one must be.
    const __m512i thr =
        _mm512_sub_epi32(_mm512_max_epi32(_mm512_max_epi32(w.t0, w.t1), w.t2), w.slack);
    const __mmask16 w0 = _mm512_cmpge_epi32_mask(w.t0, thr);
    const __mmask16 w1 = _mm512_cmpge_epi32_mask(w.t1, thr);
    const __mmask16 w2 = _mm512_cmpge_epi32_mask(w.t2, thr);
    const auto sure = static_cast<__mmask16>((w0 ^ w1 ^ w2) & ~(w0 & w1 & w2));
    // The voxel moved to last time: in the region (the walk ends there), else marked.
    const __mmask16 stop = _mm512_test_epi32_mask(cur_r, pending);
    cur_b = _mm512_mask_or_epi32(cur_b, static_cast<__mmask16>(~stop), cur_b, pending);
    marked = _mm512_mask_add_epi32(marked, static_cast<__mmask16>(tested & ~stop), marked, one);
    const auto go = static_cast<__mmask16>(active & ~stop);
    handing = static_cast<__mmask16>(handing | (go & ~sure));
    const auto steps = static_cast<__mmask16>(go & sure);
    // Lanes that stopped or hand over take no more steps.
    w.left = _mm512_maskz_sub_epi32(steps, w.left, one);
    const auto m0 = static_cast<__mmask16>(steps & w0);
    const auto m1 = static_cast<__mmask16>(steps & w1);
    const auto m2 = static_cast<__mmask16>(steps & w2);
    w.t0 = _mm512_mask_sub_epi32(w.t0, m0, w.t0, w.d0);
    w.t1 = _mm512_mask_sub_epi32(w.t1, m1, w.t1, w.d1);
    w.t2 = _mm512_mask_sub_epi32(w.t2, m2, w.t2, w.d2);
    const __m512i voxel = w.move(m0, m1, m2);
    const __m512i word = _mm512_srli_epi32(voxel, 5);
    const __mmask16 moved = _mm512_mask_cmpneq_epi32_mask(steps, word, cur_w);
    pendSixteen(moved, cur_w, cur_b, pend_w, pend_b);
    cur_w = _mm512_mask_mov_epi32(cur_w, moved, word);
    cur_b = _mm512_maskz_mov_epi32(static_cast<__mmask16>(~moved), cur_b);
    cur_r = _mm512_mask_i32gather_epi32(cur_r, moved, word, culled, 4);
    pending = _mm512_maskz_sllv_epi32(steps, one, _mm512_and_si512(voxel, low5));
  }
  n_pend = static_cast<std::size_t>(pend_w - pend_start);
  return counts;
}

/// The backward walks' steps four at a time in AVX2 lanes, as walkEightBack: the same decision
/// (the latest head, ties to the lower axis, winning by more than the bound, else the walk is
/// handed over), the region's word gathered when a lane moves to another word and the voxel
/// tested (and marked) one iteration later. Blocks entered are not listed (finishPended takes
/// them from the pended words). Returns the counts of the walks not handed over; their ids go to
/// `handed_over`.
[[DENSEMAP_AVX2]] DenseMarks::BackWalkCounts walkFourBack(const DenseMarks::QueuedBackWalk* walks,
                                                          std::size_t n,
                                                          const std::uint64_t* culled, WideOut& out,
                                                          std::vector<std::uint32_t>& handed_over) {
  const __m256i one = _mm256_set1_epi64x(1), zero = _mm256_setzero_si256(),
                low6 = _mm256_set1_epi64x(63);
  const __m256d none = _mm256_set1_pd(-std::numeric_limits<double>::infinity());
  __m256d h0 = _mm256_setzero_pd(), h1 = h0, h2 = h0, d0 = h0, d1 = h0, d2 = h0, bound = h0;
  __m256i n0 = zero, n1 = zero, n2 = zero;  // crossings left per axis (next, as BackwardWalk)
  FourPlaces p{zero, zero, zero, zero, zero};
  __m256i left = zero, marked = zero;
  // cur_b: the marks so far in the word of the lane's voxel (p.voxel() >> 6); cur_r: the
  // region's bits of that word.
  __m256i cur_b = zero, cur_r = zero;
  __m256i pending = zero;  // the bit of the voxel moved to and not yet tested (0: none)
  int live = 0, handing = 0;
  std::size_t lane_walk[4] = {0, 0, 0, 0};
  std::size_t next = 0;
  DenseMarks::BackWalkCounts counts;
  alignas(32) std::int64_t marked_at[4];
  std::uint64_t* pend_w = out.pend_w + out.n_pend;  // (locals: see walkFour)
  std::uint64_t* pend_b = out.pend_b + out.n_pend;
  const auto* culled_words = reinterpret_cast<const long long*>(culled);
  while (true) {
    __m256i active = _mm256_cmpgt_epi64(left, zero);
    const __m256i untested = _mm256_cmpeq_epi64(pending, zero);
    int act = bitsOf(active);
    const int tst = ~bitsOf(untested) & 0xf;
    if ((act | tst) != 0xf) {
      const int done = live & ~(act | tst);
      pendFour(done, _mm256_srli_epi64(p.voxel(), 6), cur_b, pend_w, pend_b);
      if (done != 0) {
        _mm256_store_si256(reinterpret_cast<__m256i*>(marked_at), marked);
        for (unsigned d = static_cast<unsigned>(done); d != 0; d &= d - 1) {
          const int k = std::countr_zero(d);
          const DenseMarks::QueuedBackWalk& w = walks[lane_walk[k]];
          if (((handing >> k) & 1) != 0) {
            handed_over.push_back(w.id);
          } else {
            counts.visits += static_cast<std::size_t>(marked_at[k]);
            counts.culled += static_cast<std::size_t>(w.total - marked_at[k]);
          }
        }
        handing &= ~done;
      }
      const __m256i busy =
          _mm256_or_si256(active, _mm256_andnot_si256(untested, _mm256_set1_epi64x(-1)));
      cur_b = _mm256_and_si256(cur_b, busy);
      marked = _mm256_and_si256(marked, busy);
      for (unsigned idle = ~static_cast<unsigned>(act | tst) & 0xfU; idle != 0 && next < n;
           idle &= idle - 1, ++next) {
        const DenseMarks::QueuedBackWalk& w = walks[next];
        const int lane = std::countr_zero(idle);
        lane_walk[lane] = next;
        const __m256i k = _mm256_load_si256(reinterpret_cast<const __m256i*>(kFour.lane[lane]));
        const __m256d kd = _mm256_castsi256_pd(k);
        h0 = _mm256_blendv_pd(h0, _mm256_set1_pd(w.head[0]), kd);
        h1 = _mm256_blendv_pd(h1, _mm256_set1_pd(w.head[1]), kd);
        h2 = _mm256_blendv_pd(h2, _mm256_set1_pd(w.head[2]), kd);
        d0 = _mm256_blendv_pd(d0, _mm256_set1_pd(w.t_delta[0]), kd);
        d1 = _mm256_blendv_pd(d1, _mm256_set1_pd(w.t_delta[1]), kd);
        d2 = _mm256_blendv_pd(d2, _mm256_set1_pd(w.t_delta[2]), kd);
        bound = _mm256_blendv_pd(bound, _mm256_set1_pd(w.bound), kd);
        putLanes(n0, w.next[0], k);
        putLanes(n1, w.next[1], k);
        putLanes(n2, w.next[2], k);
        p.load(k, w.at);
        putLanes(left, w.total, k);
        const std::uint64_t word = w.at.addr >> 6;
        putLanes(cur_r, static_cast<long long>(culled[word]), k);
      }
      active = _mm256_cmpgt_epi64(left, zero);
      act = bitsOf(active);
      live = act | tst;
      if (live == 0) break;
    }
    // The next step's decision: the latest crossing (ties to the lower axis), the runner-up.
    const __m256d high01 = _mm256_max_pd(h0, h1);
    const __m256i m2 =
        _mm256_and_si256(active, _mm256_castpd_si256(_mm256_cmp_pd(h2, high01, _CMP_GT_OQ)));
    const __m256i ge01 = _mm256_castpd_si256(_mm256_cmp_pd(h0, h1, _CMP_GE_OQ));
    const __m256i not2 = _mm256_andnot_si256(m2, active);
    __m256i m0 = _mm256_and_si256(not2, ge01);
    __m256i m1 = _mm256_andnot_si256(ge01, not2);
    __m256d chosen = _mm256_blendv_pd(h1, h0, _mm256_castsi256_pd(m0));
    chosen = _mm256_blendv_pd(chosen, h2, _mm256_castsi256_pd(m2));
    __m256d runner = _mm256_max_pd(h0, h2);  // axis 1's
    runner = _mm256_blendv_pd(runner, _mm256_max_pd(h1, h2), _mm256_castsi256_pd(m0));
    runner = _mm256_blendv_pd(runner, high01, _mm256_castsi256_pd(m2));
    const __m256i wins = _mm256_and_si256(
        active,
        _mm256_castpd_si256(_mm256_cmp_pd(_mm256_sub_pd(chosen, runner), bound, _CMP_GT_OQ)));
    // The voxel moved to last time: in the region (the walk ends there), else marked.
    const __m256i stop = _mm256_andnot_si256(
        _mm256_cmpeq_epi64(_mm256_and_si256(cur_r, pending), zero), _mm256_set1_epi64x(-1));
    const __m256i mark =
        _mm256_andnot_si256(stop, _mm256_andnot_si256(untested, _mm256_set1_epi64x(-1)));
    cur_b = _mm256_or_si256(cur_b, _mm256_andnot_si256(stop, pending));
    marked = _mm256_sub_epi64(marked, mark);
    const __m256i go = _mm256_andnot_si256(stop, active);
    handing |= bitsOf(_mm256_andnot_si256(wins, go));
    const __m256i moving = _mm256_andnot_si256(stop, wins);
    m0 = _mm256_and_si256(m0, moving);
    m1 = _mm256_and_si256(m1, moving);
    const __m256i m2w = _mm256_and_si256(m2, moving);
    const __m256i steps = _mm256_or_si256(m0, _mm256_or_si256(m1, m2w));
    // Lanes that stopped or hand over take no more steps.
    left = _mm256_and_si256(left, steps);
    // head = --next >= 0 ? head - delta : -inf
    n0 = _mm256_add_epi64(n0, m0);
    n1 = _mm256_add_epi64(n1, m1);
    n2 = _mm256_add_epi64(n2, m2w);
    h0 = _mm256_blendv_pd(h0, _mm256_sub_pd(h0, d0), _mm256_castsi256_pd(m0));
    h1 = _mm256_blendv_pd(h1, _mm256_sub_pd(h1, d1), _mm256_castsi256_pd(m1));
    h2 = _mm256_blendv_pd(h2, _mm256_sub_pd(h2, d2), _mm256_castsi256_pd(m2w));
    h0 = _mm256_blendv_pd(h0, none,
                          _mm256_castsi256_pd(_mm256_and_si256(m0, _mm256_cmpgt_epi64(zero, n0))));
    h1 = _mm256_blendv_pd(h1, none,
                          _mm256_castsi256_pd(_mm256_and_si256(m1, _mm256_cmpgt_epi64(zero, n1))));
    h2 = _mm256_blendv_pd(h2, none,
                          _mm256_castsi256_pd(_mm256_and_si256(m2w, _mm256_cmpgt_epi64(zero, n2))));
    const __m256i before = p.voxel();  // its word is the one moved from (no word register)
    p.move(m0, m1, m2w);
    left = _mm256_add_epi64(left, steps);  // stepping lanes are -1
    const __m256i voxel = p.voxel();
    const __m256i word = _mm256_srli_epi64(voxel, 6);
    const __m256i moved = _mm256_andnot_si256(
        _mm256_cmpeq_epi64(_mm256_srli_epi64(_mm256_xor_si256(before, voxel), 6), zero), steps);
    pendFour(bitsOf(moved), _mm256_srli_epi64(before, 6), cur_b, pend_w, pend_b);
    cur_b = _mm256_andnot_si256(moved, cur_b);
    cur_r = _mm256_mask_i64gather_epi64(cur_r, culled_words, word, moved, 8);
    pending = _mm256_and_si256(steps, _mm256_sllv_epi64(one, _mm256_and_si256(voxel, low6)));
  }
  out.n_pend = static_cast<std::size_t>(pend_w - out.pend_w);
  return counts;
}

/// The backward walks' steps eight at a time in AVX2 lanes of 32-bit fixed-point heads
/// (DenseMarks::FixedWalk, `t` the heads): walkFourBack's walks with backwardSteps' decision
/// (the latest head) made from integers, each within (k + 1) / 2 + 2^-10 units of the double
/// head after k subtractions: a step is taken only when the latest head is above the others by
/// more than the walk's slack (steps / 2 + 4 units plus the doubles' own bound in units, rounded
/// down: toFixedBack), so the doubles' walk takes the same step and does not hand over. A lane whose decision is
/// closer than that stops, unstepped, and its walk's queue index is appended at `handed_over` +
/// `n_handed` (what it marked is part of the walk's marks; its counts are not added). An axis
/// whose crossings are all undone is not set apart: its head goes below the first crossing's
/// time (below 0 by up to a delta), so it never wins by the slack over a head left (at or above
/// 0) — at worst a near decision hands the walk over. The region's 32-bit word of a lane's
/// voxel is gathered when the lane moves to another word, and the voxel is tested (and marked)
/// one iteration later, as walkFourBack does. Marks are pended per 32-bit word; `pend_w` /
/// `pend_b` need room for (all the walks' steps + 1) + 16. Returns the counts of the walks not
/// handed over; `n_pend` is set to the marks pended.
[[DENSEMAP_AVX2]] DenseMarks::BackWalkCounts walkEightFixedBack(
    const DenseMarks::FixedWalk* walks, std::size_t n, const std::uint32_t* culled,
    std::uint32_t* pend_w, std::uint32_t* pend_b, std::uint32_t* handed_over, std::size_t& n_handed,
    std::size_t& n_pend) {
  const __m256i zero = _mm256_setzero_si256(), ones = _mm256_set1_epi32(-1),
                one = _mm256_set1_epi32(1), low5 = _mm256_set1_epi32(31),
                minus2 = _mm256_set1_epi32(-2), edge = _mm256_set1_epi32(block::kEdge),
                edge2 = _mm256_set1_epi32(block::kEdge * block::kEdge);
  __m256i h0 = zero, h1 = zero, h2 = zero, d0 = zero, d1 = zero, d2 = zero, slack = zero;
  __m256i addr = zero, flip = zero, c0 = zero, c1 = zero, c2 = zero;
  __m256i left = zero, marked = zero;  // steps to go; voxels marked
  // cur_w: the 32-bit word of the lane's voxel; cur_b: the marks so far in it; cur_r: the
  // region's bits of it; pending: the bit of the voxel moved to and not yet tested (0: none).
  __m256i cur_w = zero, cur_b = zero, cur_r = zero, pending = zero;
  unsigned live = 0, handing = 0;
  std::uint32_t lane_walk[8] = {0, 0, 0, 0, 0, 0, 0, 0};
  alignas(32) std::int32_t marked_at[8];
  std::uint32_t* const pend_start = pend_w;
  const auto* culled_words = reinterpret_cast<const int*>(culled);
  DenseMarks::BackWalkCounts counts;
  std::size_t next = 0;
  while (true) {
    __m256i active = _mm256_cmpgt_epi32(left, zero);
    __m256i tested = _mm256_andnot_si256(_mm256_cmpeq_epi32(pending, zero), ones);
    const unsigned busy = bitsOf32(_mm256_or_si256(active, tested));
    if (busy != 0xffU) {
      const unsigned done = live & ~busy;
      if (done != 0) {
        pendEight(done, cur_w, cur_b, pend_w, pend_b);
        _mm256_store_si256(reinterpret_cast<__m256i*>(marked_at), marked);
        for (unsigned d = done; d != 0; d &= d - 1) {
          const int k = std::countr_zero(d);
          const DenseMarks::FixedWalk& w = walks[lane_walk[k]];
          if (((handing >> k) & 1U) != 0) {
            handed_over[n_handed++] = w.index;
          } else {
            counts.visits += static_cast<std::size_t>(marked_at[k]);
            counts.culled += static_cast<std::size_t>(w.steps - marked_at[k]);
          }
        }
        handing &= ~done;
      }
      const __m256i keep = lanesOf(busy);
      cur_b = _mm256_and_si256(cur_b, keep);
      marked = _mm256_and_si256(marked, keep);
      unsigned now = busy;
      for (unsigned idle = ~busy & 0xffU; idle != 0 && next < n; idle &= idle - 1, ++next) {
        const DenseMarks::FixedWalk& w = walks[next];
        const int lane = std::countr_zero(idle);
        lane_walk[lane] = static_cast<std::uint32_t>(next);
        const __m256i k = lanesOf(1U << lane);
        putLanes32(h0, k, w.t[0]);
        putLanes32(h1, k, w.t[1]);
        putLanes32(h2, k, w.t[2]);
        putLanes32(d0, k, w.d[0]);
        putLanes32(d1, k, w.d[1]);
        putLanes32(d2, k, w.d[2]);
        putLanes32(slack, k, w.slack);
        putLanes32(left, k, w.steps);
        putLanes32(addr, k, w.addr);
        putLanes32(flip, k, w.flip);
        putLanes32(c0, k, w.cross[0]);
        putLanes32(c1, k, w.cross[1]);
        putLanes32(c2, k, w.cross[2]);
        const std::int32_t word = (w.addr ^ w.flip) >> 5;
        putLanes32(cur_w, k, word);
        putLanes32(cur_r, k, culled_words[word]);
        now |= 1U << lane;
      }
      live = now;
      if (now == 0) break;
      active = _mm256_cmpgt_epi32(left, zero);
    }
    // The latest head; the axes below it by more than the slack (n_a) do not step. Exactly one
    // axis within the slack: n0 + n1 + n2 == -2; with more, the decision is too close to call.
    const __m256i thr = _mm256_sub_epi32(_mm256_max_epi32(_mm256_max_epi32(h0, h1), h2), slack);
    const __m256i n0 = _mm256_cmpgt_epi32(thr, h0);
    const __m256i n1 = _mm256_cmpgt_epi32(thr, h1);
    const __m256i n2 = _mm256_cmpgt_epi32(thr, h2);
    const __m256i sure = _mm256_cmpeq_epi32(_mm256_add_epi32(_mm256_add_epi32(n0, n1), n2), minus2);
    // The voxel moved to last time: in the region (the walk ends there), else marked.
    const __m256i stop =
        _mm256_andnot_si256(_mm256_cmpeq_epi32(_mm256_and_si256(cur_r, pending), zero), ones);
    cur_b = _mm256_or_si256(cur_b, _mm256_andnot_si256(stop, pending));
    marked = _mm256_sub_epi32(marked, _mm256_andnot_si256(stop, tested));
    const __m256i go = _mm256_andnot_si256(stop, active);
    handing |= bitsOf32(_mm256_andnot_si256(sure, go));
    const __m256i steps = _mm256_and_si256(go, sure);
    // Lanes that stopped or hand over take no more steps.
    left = _mm256_and_si256(_mm256_sub_epi32(left, one), steps);
    const __m256i m0 = _mm256_andnot_si256(n0, steps);
    const __m256i m1 = _mm256_andnot_si256(n1, steps);
    const __m256i m2 = _mm256_andnot_si256(n2, steps);
    h0 = _mm256_sub_epi32(h0, _mm256_and_si256(m0, d0));
    h1 = _mm256_sub_epi32(h1, _mm256_and_si256(m1, d1));
    h2 = _mm256_sub_epi32(h2, _mm256_and_si256(m2, d2));
    // The place (FourPlaces::move in 32 bits).
    const __m256i inc =
        _mm256_or_si256(_mm256_and_si256(m0, one),
                        _mm256_or_si256(_mm256_and_si256(m1, edge), _mm256_and_si256(m2, edge2)));
    const __m256i cross =
        _mm256_or_si256(_mm256_and_si256(m0, c0),
                        _mm256_or_si256(_mm256_and_si256(m1, c1), _mm256_and_si256(m2, c2)));
    const __m256i field = _mm256_sub_epi32(_mm256_slli_epi32(inc, block::kShift), inc);
    const __m256i border = _mm256_cmpeq_epi32(_mm256_and_si256(addr, field), field);
    addr = _mm256_add_epi32(addr, _mm256_add_epi32(inc, _mm256_and_si256(border, cross)));
    const __m256i voxel = _mm256_xor_si256(addr, flip);
    const __m256i word = _mm256_srli_epi32(voxel, 5);
    const __m256i moved = _mm256_andnot_si256(_mm256_cmpeq_epi32(word, cur_w), steps);
    const unsigned moved_bits = bitsOf32(moved);
    if (moved_bits != 0) {
      pendEight(moved_bits, cur_w, cur_b, pend_w, pend_b);
      cur_w = _mm256_blendv_epi8(cur_w, word, moved);
      cur_b = _mm256_andnot_si256(moved, cur_b);
      cur_r = _mm256_mask_i32gather_epi32(cur_r, culled_words, word, moved, 4);
    }
    pending = _mm256_and_si256(steps, _mm256_sllv_epi32(one, _mm256_and_si256(voxel, low5)));
  }
  n_pend = static_cast<std::size_t>(pend_w - pend_start);
  return counts;
}
#undef DENSEMAP_AVX2
#pragma GCC diagnostic pop
#endif

/// Room for the marks pended (words and marks) of walks of `steps` steps in all.
template <class Word>
void pendRoom(std::size_t steps, std::vector<Word>& pend_w, std::vector<Word>& pend_b) {
  const std::size_t room = steps + 16;
  if (pend_w.size() < room) {
    pend_w.resize(std::max(room, 2 * pend_w.size()));
    pend_b.resize(pend_w.size());
  }
}
/// pendRoom, and room for the blocks entered.
void makeRoom(std::size_t steps, std::vector<std::uint32_t>& entered,
              std::vector<std::uint64_t>& pend_w, std::vector<std::uint64_t>& pend_b) {
  const std::size_t room = steps + 16;
  if (entered.size() < room) entered.resize(std::max(room, 2 * entered.size()));
  pendRoom(steps, pend_w, pend_b);
}

}  // namespace

bool DenseMarks::hasWideWalks() { return hasWideLanes(); }
bool DenseMarks::hasFourWalks() { return hasFourLanes(); }

// The first-touch bookkeeping of this loop (touchIn) kept in locals: seen_'s byte stores may
// alias any member, which would reload the count and the arrays' pointers after each store.
void DenseMarks::finishQueued(std::size_t n_pend, std::size_t n_entered) {
  std::uint64_t* const words = masks_[0].data();
  const std::uint64_t* const pend_w = pend_w_.data();
  const std::uint64_t* const pend_b = pend_b_.data();
  for (std::size_t i = 0; i < n_pend; ++i) words[pend_w[i]] |= pend_b[i];
  std::uint8_t* const seen = seen_.data();
  std::uint32_t* const touched = touched_.data();
  const std::uint32_t* const entered = entered_.data();
  std::size_t count = touched_count_;
  for (std::size_t i = 0; i < n_entered; ++i) touchIn(entered[i], seen, touched, count);
  touched_count_ = count;
}

void DenseMarks::finishPended(std::size_t n_pend) {
  std::uint64_t* const words = masks_[0].data();
  const std::uint64_t* const pend_w = pend_w_.data();
  const std::uint64_t* const pend_b = pend_b_.data();
  std::uint8_t* const seen = seen_.data();
  for (std::size_t i = 0; i < n_pend; ++i) {
    const std::uint64_t w = pend_w[i];
    words[w] |= pend_b[i];
    seen[w / block::kMaskWords] = 1;  // listed later (unlisted_)
  }
  if (n_pend != 0) unlisted_ = true;
}

void DenseMarks::finishPended32(std::size_t n_pend) {
  // The masks' 64-bit words read as pairs of 32-bit ones (little-endian: the low half first).
  using Word32 [[gnu::may_alias]] = std::uint32_t;
  auto* const words = reinterpret_cast<Word32*>(masks_[0].data());
  const std::uint32_t* const pend_w = pend32_w_.data();
  const std::uint32_t* const pend_b = pend32_b_.data();
  std::uint8_t* const seen = seen_.data();
  constexpr unsigned kWords32 = block::kVoxels / 32;
  for (std::size_t i = 0; i < n_pend; ++i) {
    const std::uint32_t w = pend_w[i];
    words[w] |= pend_b[i];
    seen[w / kWords32] = 1;  // listed later (unlisted_)
  }
  if (n_pend != 0) unlisted_ = true;
}

#ifdef DENSEMAP_WIDE_WALKS
namespace {

/// The power of two that puts `last` (in (2^-500, 2^500)) at 2^28 to 2^29 units: 2^(28 - e)
/// for `last` in [2^e, 2^(e+1)) (scaling by it is exact).
double unitsFor(double last) {
  std::uint64_t bits;
  std::memcpy(&bits, &last, sizeof bits);
  const int e = static_cast<int>((bits >> 52) & 0x7ffU) - 1023;
  const std::uint64_t scale_bits = static_cast<std::uint64_t>(1023 + 28 - e) << 52;
  double scale;
  std::memcpy(&scale, &scale_bits, sizeof scale);
  return scale;
}

/// Place `at` in `f`'s terms: FourPlaces::load's mirrored place in 32 bits.
void fixedPlace(const DenseMarks::WalkPlace& at, DenseMarks::FixedWalk& f) {
  std::int32_t flip = 0;
#pragma GCC unroll 3
  for (int a = 0; a < 3; ++a) {
    const std::int32_t unit = std::int32_t{1} << (block::kShift * a);
    if (at.small[a] < 0) flip |= (block::kEdge - 1) * unit;
    f.cross[a] = at.wrap[a] + (block::kEdge - 1) * at.small[a] - block::kEdge * unit;
  }
  f.flip = flip;
  f.addr = static_cast<std::int32_t>(at.addr) ^ flip;  // below 2^30: the box's bits
}

/// A forward walk's times (`times`: t_max[3] then t_delta[3], adjacent), its last crossing's
/// time `last` and its steps in kFixedEight's terms (f's t, d, slack and steps); false when they
/// are out of its range.
[[gnu::target("avx2")]] bool fixedTimes(const double* times, double last, std::int32_t steps,
                                        DenseMarks::FixedWalk& f) {
  if (!(last > 0x1p-500 && last < 0x1p500) || steps <= 0 || steps > (1 << 20)) return false;
  // Units of 2^(e - 28) for a last time in [2^e, 2^(e+1)): it is 2^28 to 2^29 units.
  const double scale = unitsFor(last);
  // The times and deltas four at a time: t0 t1 t2 d0, then t2 d0 d1 d2. Clamped at 2^30 (above
  // any decision's threshold: never chosen); to nearest.
  static_assert(offsetof(DenseMarks::FixedWalk, d) ==
                offsetof(DenseMarks::FixedWalk, t) + 3 * sizeof(std::int32_t));
  const __m256d sc = _mm256_set1_pd(scale);
  const __m256d x = _mm256_mul_pd(_mm256_loadu_pd(times), sc);
  const __m256d y = _mm256_mul_pd(_mm256_loadu_pd(times + 2), sc);
  const __m256d low = _mm256_set1_pd(-0x1p29), cap = _mm256_set1_pd(0x1p30);
  // In range (not NaN), the deltas not negative.
  if ((_mm256_movemask_pd(_mm256_cmp_pd(x, low, _CMP_GE_OQ)) &
       _mm256_movemask_pd(_mm256_cmp_pd(y, low, _CMP_GE_OQ)) &
       (_mm256_movemask_pd(_mm256_cmp_pd(y, _mm256_setzero_pd(), _CMP_GE_OQ)) | 1)) != 0xf) {
    return false;
  }
  _mm_storeu_si128(reinterpret_cast<__m128i*>(f.t), _mm256_cvtpd_epi32(_mm256_min_pd(x, cap)));
  _mm_storeu_si128(reinterpret_cast<__m128i*>(f.t + 2), _mm256_cvtpd_epi32(_mm256_min_pd(y, cap)));
  f.slack = (steps >> 1) + 3;
  f.steps = steps;
  return true;
}

/// `w` (queue index `index`) in kFixedEight's terms; false when its times are out of range.
[[gnu::target("avx2")]] bool toFixed(const DenseMarks::QueuedWalk& w, std::uint32_t index,
                                     DenseMarks::FixedWalk& f) {
  static_assert(offsetof(DenseMarks::QueuedWalk, t_delta) ==
                offsetof(DenseMarks::QueuedWalk, t_max) + 3 * sizeof(double));
  if (!fixedTimes(w.t_max, w.t_last, w.steps, f)) return false;
  fixedPlace(w.at, f);
  f.index = index;
  return true;
}

/// Eight 32-bit lanes from memory; two halves of four as one vector.
[[gnu::target("avx2"), gnu::always_inline]] inline __m256i load8(const std::int32_t* p) {
  return _mm256_load_si256(reinterpret_cast<const __m256i*>(p));
}
[[gnu::target("avx2"), gnu::always_inline]] inline __m256i whole(const __m128i (&v)[2]) {
  return _mm256_set_m128i(v[1], v[0]);
}
/// The lanes of `r` (startTraversalLanes') that `lanes` names in kFixedEight's terms, eight at a
/// time: fixedTimes (the times and deltas, the slack and the steps: the first eight fields of a
/// FixedWalk) of each, the same operations side by side, a vector per field in `f`. Returns
/// the lanes in its range with a counted walk (kClean, countedTotal from kCountedStepsFrom) whose
/// end key is in the box of keys [lo, lo + span) per axis.
[[gnu::target("avx2"), gnu::always_inline]] inline unsigned fixedFields(
    const TraversalLanes& r, unsigned lanes, const unsigned (&lo)[3], const unsigned (&span)[3],
    __m256i (&f)[8]) {
  const __m256i total =
      _mm256_add_epi32(_mm256_add_epi32(load8(r.cr[0]), load8(r.cr[1])), load8(r.cr[2]));
  const __m256i steps = _mm256_sub_epi32(total, _mm256_set1_epi32(1));
  // Counted (total >= kCountedStepsFrom, so steps > 0) and at most 2^20 steps.
  __m256i ok = _mm256_andnot_si256(_mm256_cmpgt_epi32(_mm256_set1_epi32(kCountedStepsFrom), total),
                                   _mm256_cmpgt_epi32(_mm256_set1_epi32((1 << 20) + 1), steps));
  for (int a = 0; a < 3; ++a) {  // (key - lo) <= span - 1, unsigned
    const __m256i d =
        _mm256_sub_epi32(load8(r.key_end[a]), _mm256_set1_epi32(static_cast<int>(lo[a])));
    const __m256i top = _mm256_set1_epi32(static_cast<int>(span[a] - 1));
    ok = _mm256_and_si256(ok, _mm256_cmpeq_epi32(_mm256_max_epu32(d, top), top));
  }
  unsigned in_range = static_cast<unsigned>(_mm256_movemask_ps(_mm256_castsi256_ps(ok)));
  __m128i t[3][2], d[3][2];
  for (int h = 0; h < 2; ++h) {
    // fixedTimes: the last crossing's time in (2^-500, 2^500), units of 2^(e - 28) for it in
    // [2^e, 2^(e+1)) (unitsFor: 2^(1023 + 28 - e) as bits), the times at least -2^29 and the
    // deltas not negative (none NaN), both clamped at 2^30 and rounded to nearest.
    const __m256d last = _mm256_max_pd(
        _mm256_max_pd(_mm256_load_pd(r.la[0] + 4 * h), _mm256_load_pd(r.la[1] + 4 * h)),
        _mm256_load_pd(r.la[2] + 4 * h));
    __m256d fine = _mm256_and_pd(_mm256_cmp_pd(last, _mm256_set1_pd(0x1p-500), _CMP_GT_OQ),
                                 _mm256_cmp_pd(last, _mm256_set1_pd(0x1p500), _CMP_LT_OQ));
    const __m256i biased = _mm256_srli_epi64(_mm256_castpd_si256(last), 52);
    const __m256d scale = _mm256_castsi256_pd(
        _mm256_slli_epi64(_mm256_sub_epi64(_mm256_set1_epi64x(1023 + 1023 + 28), biased), 52));
    const __m256d low = _mm256_set1_pd(-0x1p29), cap = _mm256_set1_pd(0x1p30),
                  zero = _mm256_setzero_pd();
    for (int a = 0; a < 3; ++a) {
      const __m256d x = _mm256_mul_pd(_mm256_load_pd(r.tm[a] + 4 * h), scale);
      const __m256d y = _mm256_mul_pd(_mm256_load_pd(r.td[a] + 4 * h), scale);
      fine = _mm256_and_pd(fine, _mm256_and_pd(_mm256_cmp_pd(x, low, _CMP_GE_OQ),
                                               _mm256_cmp_pd(y, zero, _CMP_GE_OQ)));
      t[a][h] = _mm256_cvtpd_epi32(_mm256_min_pd(x, cap));
      d[a][h] = _mm256_cvtpd_epi32(_mm256_min_pd(y, cap));
    }
    in_range &= ~(static_cast<unsigned>(_mm256_movemask_pd(fine) ^ 0xf) << (4 * h));
  }
  // The eight fields (t, d, slack, steps), a vector of lanes each.
  f[0] = whole(t[0]);
  f[1] = whole(t[1]);
  f[2] = whole(t[2]);
  f[3] = whole(d[0]);
  f[4] = whole(d[1]);
  f[5] = whole(d[2]);
  f[6] = _mm256_add_epi32(_mm256_srai_epi32(steps, 1), _mm256_set1_epi32(3));
  f[7] = steps;
  return lanes & in_range;
}

/// fixedFields' fields of the lanes in a row per lane (`rows`, row l: lane l's, as a FixedWalk's
/// first eight fields). Returns fixedFields' lanes.
[[gnu::target("avx2")]] unsigned fixedLanes(const TraversalLanes& r, unsigned lanes,
                                            const unsigned (&lo)[3], const unsigned (&span)[3],
                                            std::int32_t (&rows)[8][8]) {
  __m256i f[8];
  const unsigned queued = fixedFields(r, lanes, lo, span, f);
  const __m256i u0 = _mm256_unpacklo_epi32(f[0], f[1]), u1 = _mm256_unpackhi_epi32(f[0], f[1]);
  const __m256i u2 = _mm256_unpacklo_epi32(f[2], f[3]), u3 = _mm256_unpackhi_epi32(f[2], f[3]);
  const __m256i u4 = _mm256_unpacklo_epi32(f[4], f[5]), u5 = _mm256_unpackhi_epi32(f[4], f[5]);
  const __m256i u6 = _mm256_unpacklo_epi32(f[6], f[7]), u7 = _mm256_unpackhi_epi32(f[6], f[7]);
  const __m256i v[8] = {_mm256_unpacklo_epi64(u0, u2), _mm256_unpackhi_epi64(u0, u2),
                        _mm256_unpacklo_epi64(u1, u3), _mm256_unpackhi_epi64(u1, u3),
                        _mm256_unpacklo_epi64(u4, u6), _mm256_unpackhi_epi64(u4, u6),
                        _mm256_unpacklo_epi64(u5, u7), _mm256_unpackhi_epi64(u5, u7)};
  for (int l = 0; l < 4; ++l) {  // v[l]: lanes l and l + 4, fields 0-3; v[l + 4]: fields 4-7
    _mm256_store_si256(reinterpret_cast<__m256i*>(rows[l]),
                       _mm256_permute2x128_si256(v[l], v[l + 4], 0x20));
    _mm256_store_si256(reinterpret_cast<__m256i*>(rows[l + 4]),
                       _mm256_permute2x128_si256(v[l], v[l + 4], 0x31));
  }
  return queued;
}

/// fixedFields' fields of the lanes it returns, packed in lane order, at `at` of the first eight
/// of fixedColumns' rows (`cols`, `stride` apart; 8 slots written in each). Returns those lanes.
[[gnu::target("avx2")]] unsigned fixedLaneColumns(const TraversalLanes& r, unsigned lanes,
                                                  const unsigned (&lo)[3],
                                                  const unsigned (&span)[3], std::int32_t* cols,
                                                  std::size_t stride, std::size_t at) {
  __m256i f[8];
  const unsigned queued = fixedFields(r, lanes, lo, span, f);
  const __m256i idx = _mm256_load_si256(reinterpret_cast<const __m256i*>(kEight.pack32[queued]));
  for (int k = 0; k < 8; ++k) {
    _mm256_storeu_si256(reinterpret_cast<__m256i*>(cols + k * stride + at),
                        _mm256_permutevar8x32_epi32(f[k], idx));
  }
  return queued;
}

/// Backward walk `w` (queue index `index`) in kFixedEight's terms (`t`: the heads, `steps`: the
/// total): units as toFixed's, of its latest head; an axis without crossings left at -2^30
/// (never the latest); the slack with the doubles' bound added. False when out of range.
[[gnu::target("avx2")]] bool toFixedBack(const DenseMarks::QueuedBackWalk& w, std::uint32_t index,
                                         DenseMarks::FixedWalk& f) {
  const double last = std::max(w.head[0], std::max(w.head[1], w.head[2]));
  if (!(last > 0x1p-500 && last < 0x1p500) || w.total <= 0 || w.total > (1 << 20) ||
      !(w.bound >= 0 && w.bound < 0x1p-20 * last)) {
    return false;
  }
  const double scale = unitsFor(last);
  // Heads and deltas four at a time (h0 h1 h2 d0, then h2 d0 d1 d2, as toFixed's): the heads at
  // most 2^29 units (the latest), -inf (an axis without crossings) to -2^30; the deltas clamped
  // at 2^30 (a head that goes below 0 has no crossings left: they are at or above 0).
  static_assert(offsetof(DenseMarks::QueuedBackWalk, t_delta) ==
                offsetof(DenseMarks::QueuedBackWalk, head) + 3 * sizeof(double));
  const __m256d sc = _mm256_set1_pd(scale);
  const __m256d x = _mm256_mul_pd(_mm256_loadu_pd(w.head), sc);
  const __m256d y = _mm256_mul_pd(_mm256_loadu_pd(w.head + 2), sc);
  const __m256d zero = _mm256_setzero_pd(), none = _mm256_set1_pd(-0x1p30),
                cap = _mm256_set1_pd(0x1p30);
  // The heads at or above 0 or -inf, the deltas not negative (none of them NaN).
  const int heads_ok = _mm256_movemask_pd(_mm256_or_pd(
      _mm256_cmp_pd(x, zero, _CMP_GE_OQ),
      _mm256_cmp_pd(x, _mm256_set1_pd(-std::numeric_limits<double>::infinity()), _CMP_EQ_OQ)));
  if ((heads_ok & 7) != 7 ||
      (_mm256_movemask_pd(_mm256_cmp_pd(y, zero, _CMP_GE_OQ)) & 0xe) != 0xe) {
    return false;
  }
  _mm_storeu_si128(reinterpret_cast<__m128i*>(f.t), _mm256_cvtpd_epi32(_mm256_max_pd(x, none)));
  _mm_storeu_si128(reinterpret_cast<__m128i*>(f.t + 2), _mm256_cvtpd_epi32(_mm256_min_pd(y, cap)));
  for (int a = 0; a < 3; ++a) {
    if (w.next[a] < 0) f.t[a] = -(1 << 30);  // no crossing left: never the latest
  }
  fixedPlace(w.at, f);
  // The doubles' bound in units, rounded up: below 2^9 (under 2^-20 of the latest head).
  f.slack = (w.total >> 1) + 4 + static_cast<std::int32_t>(w.bound * scale);
  f.steps = w.total;
  f.index = index;
  return true;
}

/// The queued walks in kFixedEight's terms (`convert`: toFixed or toFixedBack) at the front of
/// `fixed`, the queue indices of those out of its range in `out_of_range`, and room in the
/// pend buffers for the converted walks' marks. Returns how many were converted.
template <class Walk, class Convert>
std::size_t fixQueue(const std::vector<Walk>& queue, Convert convert,
                     std::vector<DenseMarks::FixedWalk>& fixed,
                     std::vector<std::uint32_t>& out_of_range, std::vector<std::uint32_t>& pend_w,
                     std::vector<std::uint32_t>& pend_b) {
  const std::size_t n = queue.size();
  if (fixed.size() < n) fixed.resize(n);
  out_of_range.clear();
  std::size_t m = 0, steps = 0;
  for (std::size_t i = 0; i < n; ++i) {
    if (convert(queue[i], static_cast<std::uint32_t>(i), fixed[m])) {
      steps += static_cast<std::size_t>(fixed[m].steps) + 1;
      ++m;
    } else {
      out_of_range.push_back(static_cast<std::uint32_t>(i));
    }
  }
  pendRoom(steps, pend_w, pend_b);
  return m;
}

/// walkEightFixed over `walks` or, given `cols` (fixedColumns' rows, `stride` apart),
/// walkSixteenFixed over those; the indices of those it hands over appended to `handed` (and
/// added to `counted`). Returns how many marks it pended.
std::size_t walkFixedHanding(const DenseMarks::FixedWalk* walks, const std::int32_t* cols,
                             std::size_t stride, std::size_t m, std::uint32_t* pend_w,
                             std::uint32_t* pend_b, std::vector<std::uint32_t>& handed,
                             std::size_t& counted) {
  std::size_t n_handed = handed.size();
  const std::size_t before = n_handed;
  handed.resize(n_handed + m);
  const std::size_t n_pend =
      cols != nullptr
          ? walkSixteenFixed(cols, stride, m, pend_w, pend_b, handed.data(), n_handed)
          : walkEightFixed(walks, m, pend_w, pend_b, handed.data(), n_handed);
  handed.resize(n_handed);
  counted += n_handed - before;
  return n_pend;
}

}  // namespace

unsigned DenseMarks::queueFixedLanes(const TraversalLanes& lanes, int n, const VoxelKey& first,
                                     const std::uint32_t* ids, WalkKernel kernel) {
  // The rays with a clean end (then fixedLanes picks the counted walks).
  const unsigned rays = (n >= 8 ? 0xffU : (1U << n) - 1U) & ~lanes.same & lanes.has_length &
                        ~lanes.irregular & ~lanes.unsure;
  if (rays == 0) return 0;
  constexpr int kStill[3] = {0, 0, 0};
  const WalkPlace* const at_first = placeFrom(first, kStill);  // (the memo of `first`)
  if (at_first == nullptr) return 0;
  // The box's keys: [lo, lo + span) per axis.
  const unsigned lo[3] = {min_[0] << block::kShift, min_[1] << block::kShift,
                          min_[2] << block::kShift};
  const unsigned span[3] = {n_[0] << block::kShift, n_[1] << block::kShift, n_[2] << block::kShift};
  // The place of lane l's walk in FixedWalk's terms (from the memo of its direction).
  const auto place_of = [&](int l) -> const FixedWalk& {
    const int delta[3] = {lanes.st[0][l], lanes.st[1][l], lanes.st[2][l]};
    const int slot = (delta[0] + 1) + 3 * (delta[1] + 1) + 9 * (delta[2] + 1);
    if ((memo_fixed_filled_ >> slot & 1U) == 0) {
      fixedPlace(*placeFrom(first, delta), memo_fixed_[slot]);
      memo_fixed_filled_ |= 1U << slot;
    }
    return memo_fixed_[slot];
  };
  if (n_fixed_ == 0) fixed_columns_ = walksSixteen(kernel);  // (a queue keeps its layout)
  unsigned queued = 0;
  std::size_t steps = 0;
  if (fixed_columns_) {
    if (fixed_cols_cap_ < n_fixed_ + 8) growFixedColumns();
    const std::size_t stride = fixed_cols_cap_ + 16;
    std::int32_t* const cols = fixed_cols_.data();
    queued = fixedLaneColumns(lanes, rays, lo, span, cols, stride, n_fixed_);
    std::size_t at = n_fixed_;
    for (unsigned m = queued; m != 0; m &= m - 1, ++at) {
      const int l = std::countr_zero(m);
      const FixedWalk& place = place_of(l);
      cols[8 * stride + at] = place.addr;
      cols[9 * stride + at] = place.flip;
      cols[10 * stride + at] = place.cross[0];
      cols[11 * stride + at] = place.cross[1];
      cols[12 * stride + at] = place.cross[2];
      cols[13 * stride + at] = static_cast<std::int32_t>(ids[l]);
      steps += static_cast<std::size_t>(cols[7 * stride + at]) + 1;
    }
    n_fixed_ = at;
  } else {
    alignas(32) std::int32_t rows[8][8];
    queued = fixedLanes(lanes, rays, lo, span, rows);
    if (queued == 0) return 0;
    if (fixed_queue_.size() < n_fixed_ + 8) {
      fixed_queue_.resize(std::max<std::size_t>(256, 2 * (n_fixed_ + 8)));
    }
    FixedWalk* out = fixed_queue_.data() + n_fixed_;
    static_assert(offsetof(FixedWalk, addr) == 8 * sizeof(std::int32_t));
    for (unsigned m = queued; m != 0; m &= m - 1) {
      const int l = std::countr_zero(m);
      const FixedWalk& place = place_of(l);
      std::memcpy(out, rows[l], sizeof rows[l]);  // t, d, slack, steps
      out->addr = place.addr;
      out->flip = place.flip;
      out->cross[0] = place.cross[0];
      out->cross[1] = place.cross[1];
      out->cross[2] = place.cross[2];
      out->index = ids[l];
      steps += static_cast<std::size_t>(rows[l][7]) + 1;
      ++out;
    }
    n_fixed_ = static_cast<std::size_t>(out - fixed_queue_.data());
  }
  if (queued == 0) return 0;
  fixed_steps_ += steps;
  if (at_first->addr != fixed_first_) {  // their first voxel (the sensor's), once
    setAt(static_cast<std::uint32_t>(at_first->addr >> 9),
          static_cast<int>(at_first->addr & (block::kVoxels - 1)));
    fixed_first_ = at_first->addr;
  }
  return queued;
}

void DenseMarks::growFixedColumns() {
  const std::size_t cap = std::max<std::size_t>(256, 2 * (n_fixed_ + 8));
  const std::size_t stride = cap + 16, old_stride = fixed_cols_cap_ + 16;
  std::vector<std::int32_t> cols(kFixedFields * stride);
  for (int k = 0; k < kFixedFields; ++k) {
    std::copy_n(fixed_cols_.data() + k * old_stride, n_fixed_, cols.data() + k * stride);
  }
  fixed_cols_ = std::move(cols);
  fixed_cols_cap_ = cap;
}

void DenseMarks::markFixedQueued(std::vector<std::uint32_t>& handed_over) {
  const std::size_t m = n_fixed_;
  if (m == 0) return;
  pendRoom(fixed_steps_, pend32_w_, pend32_b_);
  finishPended32(walkFixedHanding(fixed_queue_.data(),
                                  fixed_columns_ ? fixed_cols_.data() : nullptr,
                                  fixed_cols_cap_ + 16, m, pend32_w_.data(), pend32_b_.data(),
                                  handed_over, fixed_handed_));
  n_fixed_ = 0;
  fixed_steps_ = 0;
  fixed_first_ = kNoVoxel;
}

void DenseMarks::markQueuedFixed(WalkKernel kernel) {
  const std::size_t m = fixQueue(queue_, toFixed, fixed_, handed_ids_, pend32_w_, pend32_b_);
  // (handed_ids_ starts with the walks out of range: not counted as handed over.)
  const std::int32_t* cols = nullptr;
  std::size_t stride = 0;
  if (walksSixteen(kernel)) {
    stride = fixedColumnsInto(fixed_.data(), m, sixteen_rows_);
    cols = sixteen_rows_.data();
  }
  finishPended32(walkFixedHanding(fixed_.data(), cols, stride, m, pend32_w_.data(),
                                  pend32_b_.data(), handed_ids_, fixed_handed_));
  if (!handed_ids_.empty()) {
    handed_.clear();
    std::size_t handed_steps = 0;
    for (const std::uint32_t i : handed_ids_) {
      handed_.push_back(queue_[i]);
      handed_steps += static_cast<std::size_t>(queue_[i].steps) + 1;
    }
    makeRoom(handed_steps, entered_, pend_w_, pend_b_);
    WideOut out{entered_.data(), pend_w_.data(), pend_b_.data()};
    walkFour(handed_.data(), handed_.size(), out);
    finishPended(out.n_pend);
  }
  queue_.clear();
}
DenseMarks::BackWalkCounts DenseMarks::markQueuedBackFixed(
    const block::BlockMask* culled, std::vector<std::uint32_t>& handed_over, WalkKernel kernel) {
  const std::size_t m =
      fixQueue(back_queue_, toFixedBack, fixed_, handed_ids_, pend32_w_, pend32_b_);
  std::size_t n_handed = handed_ids_.size();
  const std::size_t out_of_range = n_handed;
  handed_ids_.resize(n_handed + m);
  // The region's 64-bit words read as pairs of 32-bit ones (as finishPended32's masks).
  using Word32 [[gnu::may_alias]] = std::uint32_t;
  std::size_t n_pend = 0;
  const auto* culled32 = reinterpret_cast<const Word32*>(culled[0].data());
  BackWalkCounts counts;
  if (walksSixteen(kernel)) {
    const std::size_t stride = fixedColumnsInto(fixed_.data(), m, sixteen_rows_);
    counts = walkSixteenFixedBack(sixteen_rows_.data(), stride, m, culled32, pend32_w_.data(),
                                  pend32_b_.data(), handed_ids_.data(), n_handed, n_pend);
  } else {
    counts = walkEightFixedBack(fixed_.data(), m, culled32, pend32_w_.data(), pend32_b_.data(),
                                handed_ids_.data(), n_handed, n_pend);
  }
  finishPended32(n_pend);
  handed_ids_.resize(n_handed);
  fixed_handed_ += n_handed - out_of_range;
  if (!handed_ids_.empty()) {
    back_handed_.clear();
    std::size_t handed_steps = 0;
    for (const std::uint32_t i : handed_ids_) {
      back_handed_.push_back(back_queue_[i]);
      handed_steps += static_cast<std::size_t>(back_queue_[i].total) + 1;
    }
    makeRoom(handed_steps, entered_, pend_w_, pend_b_);
    WideOut out{entered_.data(), pend_w_.data(), pend_b_.data()};
    const BackWalkCounts more =
        walkFourBack(back_handed_.data(), back_handed_.size(), culled[0].data(), out, handed_over);
    finishPended(out.n_pend);
    counts.visits += more.visits;
    counts.culled += more.culled;
  }
  return counts;
}
bool DenseMarks::queuesFixed(WalkKernel kernel) {
  return (kernel == WalkKernel::kFixedEight || kernel == WalkKernel::kBest ||
          kernel == WalkKernel::kFixedSixteen) &&
         hasFourWalks();
}
bool DenseMarks::walksSixteen(WalkKernel kernel) {
  return (kernel == WalkKernel::kFixedSixteen || kernel == WalkKernel::kBest) && hasWideWalks();
}
#else
bool DenseMarks::queuesFixed(WalkKernel) { return false; }
bool DenseMarks::walksSixteen(WalkKernel) { return false; }
unsigned DenseMarks::queueFixedLanes(const TraversalLanes&, int, const VoxelKey&,
                                     const std::uint32_t*, WalkKernel) {
  return 0;
}
void DenseMarks::growFixedColumns() {}
void DenseMarks::markFixedQueued(std::vector<std::uint32_t>&) {}
void DenseMarks::markQueuedFixed(WalkKernel) { markQueued(WalkKernel::kScalar); }
DenseMarks::BackWalkCounts DenseMarks::markQueuedBackFixed(
    const block::BlockMask* culled, std::vector<std::uint32_t>& handed_over, WalkKernel) {
  return markQueuedBack(culled, handed_over, WalkKernel::kScalar);
}
#endif

void DenseMarks::markQueued(WalkKernel kernel) {
  const std::size_t n = queue_.size();
  if (n == 0) return;
  std::uint64_t* words = masks_[0].data();
  std::size_t steps = 0;
  for (const QueuedWalk& w : queue_) steps += static_cast<std::size_t>(w.steps) + 1;
  makeRoom(steps, entered_, pend_w_, pend_b_);
  std::size_t n_entered = 0;
#ifdef DENSEMAP_WIDE_WALKS
  if (kernel == WalkKernel::kWideEight && hasWideWalks()) {
    WideOut out{entered_.data(), pend_w_.data(), pend_b_.data()};
    walkEight(queue_.data(), n, out);
    finishQueued(out.n_pend, out.n_entered);
    queue_.clear();
    return;
  }
  if (queuesFixed(kernel)) {
    markQueuedFixed(kernel);
    return;
  }
  if (kernel == WalkKernel::kFour && hasFourWalks()) {
    WideOut out{entered_.data(), pend_w_.data(), pend_b_.data()};
    walkFour(queue_.data(), n, out);
    finishPended(out.n_pend);
    queue_.clear();
    return;
  }
#endif
  (void)kernel;
  for (const QueuedWalk& w : queue_) {
    TraversalStart s;
    for (int a = 0; a < 3; ++a) {
      s.t_max[a] = w.t_max[a];
      s.t_delta[a] = w.t_delta[a];
    }
    PlaceSteps place{words, nullptr, entered_.data() + n_entered, 0, 0, w.at};
    countedSteps(s, w.steps + 1, place);
    n_entered += place.n_entered;
  }
  finishQueued(0, n_entered);
  queue_.clear();
}

DenseMarks::BackWalkCounts DenseMarks::markQueuedBack(const block::BlockMask* culled,
                                                      std::vector<std::uint32_t>& handed_over,
                                                      WalkKernel kernel) {
  BackWalkCounts counts;
  const std::size_t n = back_queue_.size();
  if (n == 0) return counts;
  std::uint64_t* words = masks_[0].data();
  const std::uint64_t* culled_words = culled[0].data();
  std::size_t steps = 0;
  for (const QueuedBackWalk& w : back_queue_) steps += static_cast<std::size_t>(w.total) + 1;
  makeRoom(steps, entered_, pend_w_, pend_b_);
  std::size_t n_entered = 0;
#ifdef DENSEMAP_WIDE_WALKS
  if (kernel == WalkKernel::kWideEight && hasWideWalks()) {
    WideOut out{entered_.data(), pend_w_.data(), pend_b_.data()};
    counts = walkEightBack(back_queue_.data(), n, culled_words, out, handed_over);
    finishQueued(out.n_pend, out.n_entered);
    back_queue_.clear();
    return counts;
  }
  if (queuesFixed(kernel)) {
    counts = markQueuedBackFixed(culled, handed_over, kernel);
    back_queue_.clear();
    return counts;
  }
  if (kernel == WalkKernel::kFour && hasFourWalks()) {
    WideOut out{entered_.data(), pend_w_.data(), pend_b_.data()};
    counts = walkFourBack(back_queue_.data(), n, culled_words, out, handed_over);
    finishPended(out.n_pend);
    back_queue_.clear();
    return counts;
  }
#endif
  (void)kernel;
  for (const QueuedBackWalk& w : back_queue_) {
    BackwardWalk walk;
    for (int a = 0; a < 3; ++a) {
      walk.s.t_delta[a] = w.t_delta[a];
      walk.head[a] = w.head[a];
      walk.next[a] = w.next[a];
    }
    walk.bound = w.bound;
    walk.total = static_cast<std::size_t>(w.total);
    PlaceSteps place{words, culled_words, entered_.data() + n_entered, 0, 0, w.at};
    bool handover = false;
    detail::backwardSteps(walk, place, handover);
    n_entered += place.n_entered;
    if (handover) {
      handed_over.push_back(w.id);
    } else {
      counts.visits += place.marked;
      counts.culled += walk.total - place.marked;
    }
  }
  finishQueued(0, n_entered);
  back_queue_.clear();
  return counts;
}

}  // namespace densemap
