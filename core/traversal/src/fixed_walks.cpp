// DenseMarks' fixed-point walks: queued walks converted to 32-bit fixed point (each decision
// checked to win by more than the rounding's bound), walked eight or sixteen at a time, the
// walks that cannot be converted or decided handed to the four-lane kernel.
#include "walk_lanes.hpp"

namespace densemap {

using namespace walks;

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
[[gnu::target("avx2"), gnu::always_inline]] inline unsigned fixedFields(const TraversalLanes& r,
                                                                        unsigned lanes,
                                                                        const unsigned (&lo)[3],
                                                                        const unsigned (&span)[3],
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
      cols != nullptr ? walkSixteenFixed(cols, stride, m, pend_w, pend_b, handed.data(), n_handed)
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
  finishPended32(walkFixedHanding(
      fixed_queue_.data(), fixed_columns_ ? fixed_cols_.data() : nullptr, fixed_cols_cap_ + 16, m,
      pend32_w_.data(), pend32_b_.data(), handed_over, fixed_handed_));
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
DenseMarks::BackWalkCounts DenseMarks::markQueuedBackFixed(const block::BlockMask* culled,
                                                           std::vector<std::uint32_t>& handed_over,
                                                           WalkKernel kernel) {
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
DenseMarks::BackWalkCounts DenseMarks::markQueuedBackFixed(const block::BlockMask* culled,
                                                           std::vector<std::uint32_t>& handed_over,
                                                           WalkKernel) {
  return markQueuedBack(culled, handed_over, WalkKernel::kScalar);
}
#endif

}  // namespace densemap
