// The queued walks eight at a time in AVX2 lanes of 32-bit fixed-point times (forward and
// backward).
#include "walk_lanes.hpp"

#ifdef DENSEMAP_WIDE_WALKS
// GCC 12's AVX-512 intrinsics start some results from _mm512_undefined_* (its bug 105593).
#pragma GCC diagnostic push
#pragma GCC diagnostic ignored "-Wmaybe-uninitialized"
#pragma GCC diagnostic ignored "-Wuninitialized"
#define DENSEMAP_AVX2 gnu::target("avx2")

namespace densemap::walks {
namespace {

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

}  // namespace

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

/// The backward walks' steps eight at a time in AVX2 lanes of 32-bit fixed-point heads
/// (DenseMarks::FixedWalk, `t` the heads): walkFourBack's walks with backwardSteps' decision
/// (the latest head) made from integers, each within (k + 1) / 2 + 2^-10 units of the double
/// head after k subtractions: a step is taken only when the latest head is above the others by
/// more than the walk's slack (steps / 2 + 4 units plus the doubles' own bound in units, rounded
/// down: toFixedBack), so the doubles' walk takes the same step and does not hand over. A lane
/// whose decision is closer than that stops, unstepped, and its walk's queue index is appended at
/// `handed_over` + `n_handed` (what it marked is part of the walk's marks; its counts are not
/// added). An axis whose crossings are all undone is not set apart: its head goes below the first
/// crossing's time (below 0 by up to a delta), so it never wins by the slack over a head left (at
/// or above 0) — at worst a near decision hands the walk over. The region's 32-bit word of a lane's
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

}  // namespace densemap::walks
#undef DENSEMAP_AVX2
#pragma GCC diagnostic pop
#endif
