// The queued walks four at a time in AVX2 lanes of double times (forward and backward): the
// kernel fixed-point walks hand their near-ties to.
#include "walk_lanes.hpp"

#ifdef DENSEMAP_WIDE_WALKS
// GCC 12's AVX-512 intrinsics start some results from _mm512_undefined_* (its bug 105593).
#pragma GCC diagnostic push
#pragma GCC diagnostic ignored "-Wmaybe-uninitialized"
#pragma GCC diagnostic ignored "-Wuninitialized"
#define DENSEMAP_AVX2 gnu::target("avx2")

namespace densemap::walks {
namespace {

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

}  // namespace

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

}  // namespace densemap::walks
#undef DENSEMAP_AVX2
#pragma GCC diagnostic pop
#endif
