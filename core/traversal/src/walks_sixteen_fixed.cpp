// The queued walks sixteen at a time in AVX-512 lanes of 32-bit fixed-point times (forward
// and backward), and the column layout they refill their lanes from.
#include "walk_lanes.hpp"

#ifdef DENSEMAP_WIDE_WALKS
// GCC 12's AVX-512 intrinsics start some results from _mm512_undefined_* (its bug 105593).
#pragma GCC diagnostic push
#pragma GCC diagnostic ignored "-Wmaybe-uninitialized"
#pragma GCC diagnostic ignored "-Wuninitialized"
#define DENSEMAP_AVX512_FIXED gnu::target("avx512f,avx512vl,avx512dq,popcnt,bmi2")

namespace densemap::walks {
namespace {

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
    __m512i* const fields[kFixedFields] = {&t0,   &t1,   &t2,   &d0, &d1, &d2, &slack,
                                           &left, &addr, &flip, &c0, &c1, &c2, &ids};
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

}  // namespace

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
    std::uint32_t* pend_w, std::uint32_t* pend_b, std::uint32_t* handed_over, std::size_t& n_handed,
    std::size_t& n_pend) {
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

}  // namespace densemap::walks
#undef DENSEMAP_AVX512_FIXED
#pragma GCC diagnostic pop
#endif
