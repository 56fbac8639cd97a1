// DenseMarks::markQueued: the queued forward walks' steps, one walk at a time or eight side by
// side in AVX-512 lanes (same axis choice, same double additions, same marks).
#include <algorithm>
#include <bit>

#include "densemap/geometry/ray_traversal.hpp"
#include "densemap/map/dense_marks.hpp"

#if defined(__x86_64__) && defined(__GNUC__)
#include <immintrin.h>
#define DENSEMAP_WIDE_WALKS 1
#endif

namespace densemap {
namespace {

/// countedSteps' steps on a queued walk's bit address (as DenseMarks::Cursor::move, with the
/// blocks entered listed for the first-touch bookkeeping afterwards).
struct AddressSteps {
  std::uint64_t* words;
  std::uint32_t* entered;
  std::size_t n_entered;
  std::uint64_t addr;
  std::int32_t left[3];
  std::int32_t small[3];
  std::int32_t wrap[3];
  template <int A>
  [[gnu::always_inline]] void step() {
    if (--left[A] == 0) {
      left[A] = block::kEdge;
      addr += static_cast<std::uint64_t>(static_cast<std::int64_t>(wrap[A]));
      entered[n_entered++] = static_cast<std::uint32_t>(addr >> 9);
    } else {
      addr += static_cast<std::uint64_t>(static_cast<std::int64_t>(small[A]));
    }
    words[addr >> 6] |= std::uint64_t{1} << (addr & 63U);
  }
};

/// One walk's steps; returns the blocks entered (at most its steps) written to `entered`.
std::size_t walkOne(const DenseMarks::QueuedWalk& w, std::uint64_t* words,
                    std::uint32_t* entered) {
  TraversalStart s;
  for (int a = 0; a < 3; ++a) {
    s.t_max[a] = w.t_max[a];
    s.t_delta[a] = w.t_delta[a];
  }
  AddressSteps steps{words, entered, 0, w.addr, {}, {}, {}};
  for (int a = 0; a < 3; ++a) {
    steps.left[a] = w.left[a];
    steps.small[a] = w.small[a];
    steps.wrap[a] = w.wrap[a];
  }
  countedSteps(s, w.steps + 1, steps);
  return steps.n_entered;
}

#ifdef DENSEMAP_WIDE_WALKS
// GCC 12's AVX-512 intrinsics start some results from _mm512_undefined_* (its bug 105593).
#pragma GCC diagnostic push
#pragma GCC diagnostic ignored "-Wmaybe-uninitialized"
/// Writes the lanes' words and marks, packed, at `w` and `b` (8 slots each); returns how many.
[[gnu::target("avx512f,avx512vl,avx512dq"), gnu::always_inline]] inline std::size_t pendLanes(
    __mmask8 lanes, __m512i words, __m512i bits, std::uint64_t* w, std::uint64_t* b) {
  _mm512_storeu_si512(w, _mm512_maskz_compress_epi64(lanes, words));
  _mm512_storeu_si512(b, _mm512_maskz_compress_epi64(lanes, bits));
  return static_cast<std::size_t>(std::popcount(static_cast<unsigned>(lanes)));
}

/// The walks' steps eight at a time, one walk a lane: countedSteps' choice (the smallest tMax,
/// ties to the higher axis) as compare masks; a lane whose walk is done takes the next one, so
/// the lanes' walks are at different distances from their (shared) origin and their marks seldom
/// fall on one word (a word's ORs one after the other wait on each other). Returns the blocks
/// entered written to `entered`, which must have room for (all the walks' steps) + 8.
[[gnu::target("avx512f,avx512vl,avx512dq")]] std::size_t walkEight(
    const DenseMarks::QueuedWalk* walks, std::size_t n, std::uint64_t* words,
    std::uint32_t* entered, std::uint64_t* pend_w, std::uint64_t* pend_b) {
  const __m512i one = _mm512_set1_epi64(1), edge = _mm512_set1_epi64(block::kEdge),
                zero = _mm512_setzero_si512(), low6 = _mm512_set1_epi64(63);
  __m512d t0 = _mm512_setzero_pd(), t1 = t0, t2 = t0, d0 = t0, d1 = t0, d2 = t0;
  __m512i l0 = zero, l1 = zero, l2 = zero, s0 = zero, s1 = zero, s2 = zero, r0 = zero, r1 = zero,
          r2 = zero, addr = zero, left = zero;  // left: the lane's steps to go
  __m512i cur_w = zero, cur_b = zero;  // per lane: the word being marked, its marks so far
  std::size_t next = 0, n_entered = 0, n_pend = 0;
  __mmask8 live = 0;  // lanes with a walk (its last word's marks not pended yet)
  while (true) {
    __mmask8 active = _mm512_cmpgt_epi64_mask(left, zero);
    if (active != 0xff) {
      // Walks just done: their last word's marks.
      const auto done = static_cast<__mmask8>(live & ~active);
      n_pend += pendLanes(done, cur_w, cur_b, pend_w + n_pend, pend_b + n_pend);
      cur_b = _mm512_maskz_mov_epi64(active, cur_b);
      live = active;
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
        l0 = _mm512_mask_set1_epi64(l0, k, w.left[0]);
        l1 = _mm512_mask_set1_epi64(l1, k, w.left[1]);
        l2 = _mm512_mask_set1_epi64(l2, k, w.left[2]);
        s0 = _mm512_mask_set1_epi64(s0, k, w.small[0]);
        s1 = _mm512_mask_set1_epi64(s1, k, w.small[1]);
        s2 = _mm512_mask_set1_epi64(s2, k, w.small[2]);
        r0 = _mm512_mask_set1_epi64(r0, k, w.wrap[0]);
        r1 = _mm512_mask_set1_epi64(r1, k, w.wrap[1]);
        r2 = _mm512_mask_set1_epi64(r2, k, w.wrap[2]);
        addr = _mm512_mask_set1_epi64(addr, k, static_cast<long long>(w.addr));
        left = _mm512_mask_set1_epi64(left, k, w.steps);
        cur_w = _mm512_mask_set1_epi64(cur_w, k, static_cast<long long>(w.addr >> 6));
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
    l0 = _mm512_mask_mov_epi64(l0, w0, edge);
    l1 = _mm512_mask_mov_epi64(l1, w1, edge);
    l2 = _mm512_mask_mov_epi64(l2, w2, edge);
    // The blocks entered, packed (the store writes 8 slots; the count moves by those entered).
    const auto wrapped = static_cast<__mmask8>(w0 | w1 | w2);
    const __m256i blocks = _mm512_cvtepi64_epi32(_mm512_srli_epi64(addr, 9));
    _mm256_storeu_si256(reinterpret_cast<__m256i*>(entered + n_entered),
                        _mm256_maskz_compress_epi32(wrapped, blocks));
    n_entered += static_cast<std::size_t>(std::popcount(static_cast<unsigned>(wrapped)));
    // The marks: gathered per lane while it stays in one word, pended when it moves on.
    const __m512i word = _mm512_srli_epi64(addr, 6);
    const __mmask8 moved = _mm512_mask_cmpneq_epi64_mask(active, word, cur_w);
    n_pend += pendLanes(moved, cur_w, cur_b, pend_w + n_pend, pend_b + n_pend);
    cur_w = _mm512_mask_mov_epi64(cur_w, moved, word);
    cur_b = _mm512_mask_mov_epi64(cur_b, moved, zero);
    cur_b = _mm512_mask_or_epi64(cur_b, active, cur_b,
                                 _mm512_sllv_epi64(one, _mm512_and_si512(addr, low6)));
  }
  for (std::size_t i = 0; i < n_pend; ++i) words[pend_w[i]] |= pend_b[i];
  return n_entered;
}
#pragma GCC diagnostic pop
#endif

}  // namespace

bool DenseMarks::hasWideWalks() {
#ifdef DENSEMAP_WIDE_WALKS
  static const bool has = [] {
    __builtin_cpu_init();
    return __builtin_cpu_supports("avx512f") != 0 && __builtin_cpu_supports("avx512vl") != 0 &&
           __builtin_cpu_supports("avx512dq") != 0;
  }();
  return has;
#else
  return false;
#endif
}

void DenseMarks::markQueued(WalkKernel kernel) {
  const std::size_t n = queue_.size();
  if (n == 0) return;
  std::uint64_t* words = masks_[0].data();
#ifdef DENSEMAP_WIDE_WALKS
  if (kernel == WalkKernel::kBest && hasWideWalks()) {
    std::size_t room = 16;
    for (const QueuedWalk& w : queue_) room += static_cast<std::size_t>(w.steps) + 1;
    if (entered_.size() < room) entered_.resize(std::max(room, 2 * entered_.size()));
    if (pend_w_.size() < room) {
      pend_w_.resize(std::max(room, 2 * pend_w_.size()));
      pend_b_.resize(pend_w_.size());
    }
    const std::size_t e =
        walkEight(queue_.data(), n, words, entered_.data(), pend_w_.data(), pend_b_.data());
    for (std::size_t i = 0; i < e; ++i) touch(entered_[i]);
    queue_.clear();
    return;
  }
#endif
  (void)kernel;
  for (const QueuedWalk& w : queue_) {
    const auto room = static_cast<std::size_t>(w.steps) + 1;
    if (entered_.size() < room) entered_.resize(std::max(room, 2 * entered_.size()));
    const std::size_t e = walkOne(w, words, entered_.data());
    for (std::size_t i = 0; i < e; ++i) touch(entered_[i]);
  }
  queue_.clear();
}

}  // namespace densemap
