#include "free_traversal.hpp"

#include <tbb/blocked_range.h>
#include <tbb/enumerable_thread_specific.h>
#include <tbb/parallel_for.h>

#include <algorithm>
#include <atomic>
#include <bit>
#include <cmath>
#include <deque>

#include "densemap/geometry/rounding.hpp"
#include "densemap/kernel/kernel_function.hpp"

#if defined(__x86_64__) && defined(__GNUC__)
#include <immintrin.h>

#include "densemap/traversal/ray_traversal.hpp"  // hasWideLanes
#define DENSEMAP_EVIDENCE_LANES 1
#endif

namespace densemap::kernel {
namespace {

/// A voxel within reach of a capsule: its key (VoxelKey::packed) and squared distance from the
/// capsule's axis (on the axis it may round a little below 0, which the kernel table reads as
/// 0).
struct Near {
  std::uint64_t key = 0;
  double d2 = 0.0;
};

/// One thread's blocks of one scan: a slot per block (a deque: slots never move), a hash from
/// block key to slot, and in front of it a small direct-mapped cache (a capsule's slices and
/// rows alternate between a few neighbouring blocks).
struct ThreadBlocks {
  static constexpr int kCacheSize = 16;
  static constexpr std::uint64_t kNone = ~std::uint64_t{0};
  std::deque<FreeTraversal::Block> slots;
  std::size_t used = 0;
  /// Block key -> slot: open addressing, linear probing, a power of two at most half full. A
  /// capsule's rows leave the cache below for another block about every tenth visit, so a
  /// std::unordered_map's prime modulo and node per block would show in the free stage.
  std::vector<std::pair<std::uint64_t, FreeTraversal::Block*>> index;
  std::array<std::uint64_t, kCacheSize> cache_keys{};
  std::array<FreeTraversal::Block*, kCacheSize> cache_blocks{};

  ThreadBlocks() { cache_keys.fill(kNone); }
  void reset() {
    used = 0;
    std::fill(index.begin(), index.end(),
              std::pair<std::uint64_t, FreeTraversal::Block*>{kNone, nullptr});
    cache_keys.fill(kNone);
    last_key = kNone;
  }
  std::uint64_t last_key = ~std::uint64_t{0};
  FreeTraversal::Block* last = nullptr;
  std::vector<Near> near;  // one capsule's voxels (collectVoxelsNearOn), kept

  FreeTraversal::Block& blockFor(std::uint64_t key) {
    if (key == last_key) return *last;
    last_key = key;
    last = &lookup(key);
    return *last;
  }
  FreeTraversal::Block& lookup(std::uint64_t key) {
    const std::size_t line = (key ^ (key >> 13) ^ (key >> 26)) & (kCacheSize - 1);
    if (cache_keys[line] == key) return *cache_blocks[line];
    FreeTraversal::Block* b = find(key);
    cache_keys[line] = key;
    cache_blocks[line] = b;
    return *b;
  }
  /// The slot of `key`, made (zeroed) when the scan had none.
  FreeTraversal::Block* find(std::uint64_t key) {
    if (2 * (used + 1) > index.size()) grow();
    const std::size_t mask = index.size() - 1;
    std::size_t i = static_cast<std::size_t>((key * 0x9E3779B97F4A7C15ULL) >> 20) & mask;
    while (index[i].first != key) {
      if (index[i].first == kNone) {
        if (used == slots.size()) slots.emplace_back();
        FreeTraversal::Block& b = slots[used++];
        b.key = key;
        b.sum.fill(0);
        b.mask.fill(0);
        index[i] = {key, &b};
        break;
      }
      i = (i + 1) & mask;
    }
    return index[i].second;
  }
  void grow() {
    std::vector<std::pair<std::uint64_t, FreeTraversal::Block*>> old(
        std::max<std::size_t>(1024, 2 * index.size()), {kNone, nullptr});
    old.swap(index);
    const std::size_t mask = index.size() - 1;
    for (const auto& [key, block] : old) {
      if (key == kNone) continue;
      std::size_t i = static_cast<std::size_t>((key * 0x9E3779B97F4A7C15ULL) >> 20) & mask;
      while (index[i].first != kNone) i = (i + 1) & mask;
      index[i] = {key, block};
    }
  }
};

/// Candidates at most in a capsule's box for collectVoxelsNearOn to test the box whole.
constexpr long kShortBox = 32;

/// A capsule's axis in its slices' planes, in key units (a centre's key k lies at
/// (k - 32767.5) * res): the line's squared distance qbb ob^2 + 2 qbc ob oc + qcc oc^2 of a
/// centre offset (ob, oc) from where it crosses the slice, and the box of its ellipse.
struct SliceLine {
  double qbb = 0.0, qbc = 0.0, qcc = 0.0;
  double half_b = 0.0, half_c = 0.0;  // the ellipse's half box
  int span_b = 0, span_c = 0;         // the most centres 2 * half holds
  double r2 = 0.0;                    // reach^2
  double u_per_key2 = 0.0;            // u per key unit^2 (res^2 / radius^2)
};

/// The voxels of interior slice i (crossed at qb, qc) within reach of the line, added to `sink`
/// as found: the block and cell from the slice's, row's and column's bits (a thin capsule keeps
/// a voxel or two a slice, where a list's round trip and a packed key's unpacking per voxel had
/// cost as much as the window). The window is inside the addressable range.
template <int AX, class Sink>
[[gnu::always_inline]] inline void interiorWindow(int i, double qb, double qc, const SliceLine& l,
                                                  Sink& sink) {
  constexpr int ax = AX, bx = (AX + 1) % 3, cx = (AX + 2) % 3;
  const int j0 = ceilToInt(qb - l.half_b), k0 = ceilToInt(qc - l.half_c);
  const int j_last = std::min(j0 + l.span_b - 1, static_cast<int>(qb + l.half_b));
  const int k_last = std::min(k0 + l.span_c - 1, static_cast<int>(qc + l.half_c));
  const std::uint64_t block_i = std::uint64_t(static_cast<std::uint32_t>(i) >> 3) << (13 * ax);
  const int cell_i = (i & 7) << (3 * ax);
  for (int j = j0; j <= j_last; ++j) {
    const double ob = static_cast<double>(j) - qb;
    const double row = l.qbb * ob * ob, cross = 2.0 * l.qbc * ob;
    const std::uint64_t block_ij =
        block_i | (std::uint64_t(static_cast<std::uint32_t>(j) >> 3) << (13 * bx));
    const int cell_ij = cell_i | ((j & 7) << (3 * bx));
    for (int k = k0; k <= k_last; ++k) {
      const double oc = static_cast<double>(k) - qc;
      const double d2 = row + (cross + l.qcc * oc) * oc;
      if (!(d2 < l.r2)) continue;
      sink.add(block_ij | (std::uint64_t(static_cast<std::uint32_t>(k) >> 3) << (13 * cx)),
               cell_ij | ((k & 7) << (3 * cx)), d2 * l.u_per_key2);
    }
  }
}

/// Every voxel whose centre lies within `reach` of the segment [a, b], once, slice by slice along
/// its dominant axis AX (a template argument: the axes' indices and the keys' shifts are
/// constants): the interior slices' voxels go straight to `sink` (u = d^2 * u_per_m2), the
/// others are written into `out` from index 0 (their count returned; `out` only grows: no
/// element is constructed twice) for the caller to add. In an interior slice (every point of it
/// within `reach` has its nearest point of the line on the segment) the distance is the line's:
/// a quadratic form in the centre's offset from where the line crosses the slice, fixed per
/// segment (in key units: no coordinate per candidate), tested over the rows and columns of
/// centres inside the ellipse's box (at most as many as a box of its size can hold). The few
/// end slices test the capsule's box with the segment's distance, without a branch per
/// candidate: a candidate is written, and kept when inside (a branch there would be
/// mispredicted about every other candidate). A short
/// capsule (a ray's tip) is its box, tested whole the same way. An open end (open_from at a,
/// open_to at b) drops the candidates whose nearest point of the line lies beyond it (only end
/// slices and short boxes hold such candidates).
template <int AX, class Sink>
std::size_t collectVoxelsNearOn(const VoxelGrid& grid, const Eigen::Vector3d& a,
                                const Eigen::Vector3d& b, bool open_from, bool open_to,
                                double reach, std::vector<Near>& out, double u_per_m2,
                                Sink& sink_out) {
  // The sink in a local (its counters and pointers in registers: through the reference, every
  // store to a block's sums or mask might change them), handed back on return.
  Sink sink = sink_out;
  struct HandBack {
    Sink& to;
    const Sink& from;
    ~HandBack() { to = from; }
  } hand_back{sink_out, sink};
  constexpr int ax = AX, bx = (AX + 1) % 3, cx = (AX + 2) % 3;
  const Eigen::Vector3d seg = b - a;
  const double len2 = seg.squaredNorm();
  const double inverse_len2 = 1.0 / len2;
  const double r2 = reach * reach;
  const double res = grid.resolution();
  const double inverse_res = 1.0 / res;
  // grid.keyToCoord(key), with the resolution in a register.
  const auto centreOf = [res](int key) { return VoxelGrid::keyToCoord(key, res); };
  // The keys of the first voxel centre at or after v and of the last at or before it, clamped
  // into the addressable range ([0, 65535]; a clamped candidate lies farther than `reach`).
  const auto firstCentre = [&](double v) {
    return ceilToInt(std::clamp(v * inverse_res + 32767.5, 0.0, 65535.0));
  };
  const auto lastCentre = [&](double v) {
    return static_cast<int>(std::clamp(v * inverse_res + 32767.5, 0.0, 65535.0));
  };
  // The packed key (VoxelKey::packed: 16 bits an axis) of slice i, row j, column k.
  constexpr int shift_a = 16 * ax, shift_b = 16 * bx, shift_c = 16 * cx;
  const auto keyOf = [](int i, int j, int k) {
    return (std::uint64_t(static_cast<std::uint32_t>(i)) << shift_a) |
           (std::uint64_t(static_cast<std::uint32_t>(j)) << shift_b) |
           (std::uint64_t(static_cast<std::uint32_t>(k)) << shift_c);
  };
  constexpr std::uint64_t step_c = std::uint64_t{1} << shift_c;
  // A short capsule (a ray's tip: its box a few voxels a side) is its box, each centre tested
  // with the segment's distance: slicing it cost a slice's set-up for a voxel or two.
  std::size_t n = 0;
  const int i0_box = firstCentre(std::min(a[ax], b[ax]) - reach),
            i1_box = lastCentre(std::max(a[ax], b[ax]) + reach);
  const int j0_box = firstCentre(std::min(a[bx], b[bx]) - reach),
            j1_box = lastCentre(std::max(a[bx], b[bx]) + reach);
  const int k0_box = firstCentre(std::min(a[cx], b[cx]) - reach),
            k1_box = lastCentre(std::max(a[cx], b[cx]) + reach);
  const long box_size =
      long{i1_box - i0_box + 1} * long{j1_box - j0_box + 1} * long{k1_box - k0_box + 1};
  if (box_size <= kShortBox) {
    if (box_size <= 0) return 0;
    if (out.size() < static_cast<std::size_t>(box_size))
      out.resize(static_cast<std::size_t>(box_size));
    Near* const box_out = out.data();
    for (int i = i0_box; i <= i1_box; ++i) {
      const double wa = centreOf(i) - a[ax];
      for (int j = j0_box; j <= j1_box; ++j) {
        const double wb = centreOf(j) - a[bx];
        const double dot_ab = wa * seg[ax] + wb * seg[bx];
        std::uint64_t key = keyOf(i, j, k0_box);
        for (int k = k0_box; k <= k1_box; ++k, key += step_c) {
          const double wc = centreOf(k) - a[cx];
          const double t_line = (dot_ab + wc * seg[cx]) * inverse_len2;
          const double t = std::clamp(t_line, 0.0, 1.0);
          const double da = wa - t * seg[ax], db = wb - t * seg[bx], dc = wc - t * seg[cx];
          const double d2 = da * da + db * db + dc * dc;
          box_out[n] = {key, d2};
          n += d2 < r2 && !(open_from && t_line < 0.0) && !(open_to && t_line > 1.0);
        }
      }
    }
    return n;
  }
  const Eigen::Vector3d u = seg / std::sqrt(len2);
  // The squared distance from the line of a centre offset (0, ob, oc) from the line's crossing
  // of its slice: |o|^2 - (o.u)^2 = qbb ob^2 + 2 qbc ob oc + qcc oc^2; the ellipse qform < r2
  // spans reach * sqrt(1 + u_b^2 / u_a^2) along b (and likewise c) around the crossing.
  const double qbb = 1.0 - u[bx] * u[bx], qcc = 1.0 - u[cx] * u[cx], qbc = -u[bx] * u[cx];
  const double inverse_ua2 = 1.0 / (u[ax] * u[ax]);
  const double half_b = reach * std::sqrt(1.0 + u[bx] * u[bx] * inverse_ua2) + 1e-9;
  const double half_c = reach * std::sqrt(1.0 + u[cx] * u[cx] * inverse_ua2) + 1e-9;
  // The most voxel centres an interval of 2 * half holds.
  const int span_b = static_cast<int>(2.0 * half_b * inverse_res) + 1;
  const int span_c = static_cast<int>(2.0 * half_c * inverse_res) + 1;
  const double slope_b = seg[bx] / seg[ax], slope_c = seg[cx] / seg[ax];
  // Every interior window lies inside the addressable range when the capsule's box along b and
  // c does (a voxel to spare for the crossings' rounding): then its keys need neither the
  // clamp nor the edge test (the same keys: the clamp leaves such values as they are).
  const auto inRange = [&](int axis, double half, int span) {
    return (std::min(a[axis], b[axis]) - half - res) * inverse_res + 32767.5 >= 0.0 &&
           (std::max(a[axis], b[axis]) + half + res) * inverse_res + 32767.5 <= 65534.0 - span;
  };
  const bool inside = inRange(bx, half_b, span_b) && inRange(cx, half_c, span_c);
  SliceLine line;
  line.qbb = qbb, line.qbc = qbc, line.qcc = qcc;
  line.half_b = half_b * inverse_res, line.half_c = half_c * inverse_res;
  line.span_b = span_b, line.span_c = span_c;
  line.r2 = r2 * inverse_res * inverse_res;
  line.u_per_key2 = res * res * u_per_m2;
  const double inverse_seg_ax = 1.0 / seg[ax];
  const int i0 = i0_box, i1 = i1_box;
  // The interior slices (their centres more than `reach` inside the segment's extent along
  // ax; a slice to spare at each end, as the test below may round either way) in one run: the
  // crossing stepped, no test per slice. The others, and every slice at the addressable
  // range's edge, one by one.
  const int run_first =
      inside ? std::max(i0, ceilToInt((std::min(a[ax], b[ax]) + reach) * inverse_res + 32767.5) + 1)
             : i1 + 1;
  const int run_last =
      std::min(i1, floorToInt((std::max(a[ax], b[ax]) - reach) * inverse_res + 32767.5) - 1);
  for (int i = i0; i <= i1; ++i) {
    if (i == run_first && run_first <= run_last) {
      const double x = centreOf(i);
      double qb = (a[bx] + (x - a[ax]) * slope_b) * inverse_res + 32767.5;
      double qc = (a[cx] + (x - a[ax]) * slope_c) * inverse_res + 32767.5;
      for (; i <= run_last; ++i, qb += slope_b, qc += slope_c) {
        interiorWindow<AX>(i, qb, qc, line, sink);
      }
      i = run_last;
      continue;
    }
    const double x = centreOf(i);
    // The part of the segment within `reach` of this slice along ax.
    double t0 = (x - reach - a[ax]) * inverse_seg_ax, t1 = (x + reach - a[ax]) * inverse_seg_ax;
    if (t0 > t1) std::swap(t0, t1);
    if (t0 > 0.0 && t1 < 1.0) {
      const double pb = a[bx] + (x - a[ax]) * slope_b, pc = a[cx] + (x - a[ax]) * slope_c;
      if (inside) {
        interiorWindow<AX>(i, pb * inverse_res + 32767.5, pc * inverse_res + 32767.5, line, sink);
        continue;
      }
      int j0 = 0, k0 = 0, rows = 0, columns = 0;
      // Clamped at the addressable range's edge, the window keeps its voxels inside it (it
      // had skipped the whole slice there, and lost those voxels' evidence).
      j0 = firstCentre(pb - half_b), k0 = firstCentre(pc - half_c);
      rows = std::min(span_b, lastCentre(pb + half_b) - j0 + 1);
      columns = std::min(span_c, lastCentre(pc + half_c) - k0 + 1);
      // Room for the window (written before being kept).
      const auto window = static_cast<std::size_t>(span_b * span_c);
      if (n + window > out.size()) out.resize(2 * (n + window));
      const double ob0 = centreOf(j0) - pb;
      const double oc0 = centreOf(k0) - pc;
      Near* const window_out = out.data();
      // The offsets' counters in doubles (the same small integers: no conversion a candidate).
      // d2 may round below 0 on the line: the kernel table reads it as 0.
      double fj = 0.0;
      for (int dj = 0; dj < rows; ++dj, fj += 1.0) {
        const double ob = ob0 + fj * res;
        const double row = qbb * ob * ob, cross = 2.0 * qbc * ob;
        std::uint64_t key = keyOf(i, j0 + dj, k0);
        double fk = 0.0;
        for (int dk = 0; dk < columns; ++dk, key += step_c, fk += 1.0) {
          const double oc = oc0 + fk * res;
          const double d2 = row + (cross + qcc * oc) * oc;
          window_out[n] = {key, d2};
          n += d2 < r2;
        }
      }
      continue;
    }
    t0 = std::max(t0, 0.0);
    t1 = std::min(t1, 1.0);
    if (t0 > t1) continue;
    const double yb0 = a[bx] + t0 * seg[bx], yb1 = a[bx] + t1 * seg[bx];
    const double zc0 = a[cx] + t0 * seg[cx], zc1 = a[cx] + t1 * seg[cx];
    const int j0 = firstCentre(std::min(yb0, yb1) - reach),
              j1 = lastCentre(std::max(yb0, yb1) + reach);
    const int k0 = firstCentre(std::min(zc0, zc1) - reach),
              k1 = lastCentre(std::max(zc0, zc1) + reach);
    if (j1 < j0 || k1 < k0) continue;
    const auto box = static_cast<std::size_t>(j1 - j0 + 1) * static_cast<std::size_t>(k1 - k0 + 1);
    if (n + box > out.size()) out.resize(2 * (n + box));
    Near* const box_out = out.data();
    // The centre's offset w from a and its distance from the segment, component by component
    // in the axes' order (x, y, z: the sums as a vector's dot product and squared norm make
    // them), in registers.
    std::array<double, 3> w{};
    w[ax] = x - a[ax];
    for (int j = j0; j <= j1; ++j) {
      w[bx] = centreOf(j) - a[bx];
      std::uint64_t key = keyOf(i, j, k0);
      for (int k = k0; k <= k1; ++k, key += step_c) {
        w[cx] = centreOf(k) - a[cx];
        const double t_line = (w[0] * seg[0] + w[1] * seg[1] + w[2] * seg[2]) * inverse_len2;
        const double t = std::clamp(t_line, 0.0, 1.0);
        const double d0 = w[0] - t * seg[0], d1 = w[1] - t * seg[1], d2c = w[2] - t * seg[2];
        const double d2 = d0 * d0 + d1 * d1 + d2c * d2c;
        box_out[n] = {key, d2};
        n += d2 < r2 && !(open_from && t_line < 0.0) && !(open_to && t_line > 1.0);
      }
    }
  }
  return n;
}

/// A capsule's evidence into one thread's blocks: scaled_weight * k(d / radius) per voxel, in
/// fixed point.
struct CapsuleSink {
  ThreadBlocks* blocks = nullptr;
  const SquaredKernelTable* table = nullptr;
  double scaled_weight = 0.0;
  std::size_t visits = 0;
  /// `u`: the voxel's squared distance over the radius'.
  void add(std::uint64_t block_key, int cell, double u) {
    const double w = (*table)(u);
    if (!(w > 0.0)) return;
    ++visits;
    FreeTraversal::Block& blk = blocks->blockFor(block_key);
    // w >= 0: rounding half up without llround's call.
    blk.sum[static_cast<std::size_t>(cell)] += static_cast<std::int32_t>(w * scaled_weight + 0.5);
    block::setBit(blk.mask, cell);
  }
};

/// The capsule's cells into `blocks` along the segment's dominant axis AX, each getting
/// scaled_weight * k(d / radius) in fixed point; returns the visits.
template <int AX>
std::size_t rasterise(const VoxelGrid& grid, const FreeExtent& e, double reach,
                      double scaled_weight, const SquaredKernelTable& table, ThreadBlocks& blocks) {
  const double u_per_m2 = 1.0 / (e.radius_m * e.radius_m);
  CapsuleSink sink{&blocks, &table, scaled_weight};
  const std::size_t count = collectVoxelsNearOn<AX>(grid, e.from, e.to, e.open_from, e.open_to,
                                                    reach, blocks.near, u_per_m2, sink);
  for (std::size_t q = 0; q < count; ++q) {
    const Near& v = blocks.near[q];
    sink.add(block::blockOfPacked(v.key), block::indexOfPacked(v.key), v.d2 * u_per_m2);
  }
  return sink.visits;
}

#ifdef DENSEMAP_EVIDENCE_LANES
/// FreeTraversal::addEvidence sixteen cells at a time: the same conversions, product and sum
/// (IEEE results, lane by lane).
[[gnu::target("avx512f,avx512dq,avx512vl")]] void addEvidenceWide(
    const FreeTraversal::Block& b, double inverse_scale, std::array<float, block::kVoxels>& beta,
    block::BlockMask& known) {
  const __m512d scale = _mm512_set1_pd(inverse_scale);
  for (int wd = 0; wd < block::kMaskWords; ++wd) {
    const std::uint64_t cells = b.mask[static_cast<std::size_t>(wd)];
    if (cells == 0) continue;
    known[static_cast<std::size_t>(wd)] |= cells;
    for (int q = 0; q < 8; ++q) {
      const auto lanes = static_cast<__mmask8>(cells >> (8 * q));
      if (lanes == 0) continue;
      const int first = 64 * wd + 8 * q;
      const __m512d sum = _mm512_maskz_cvtepi32_pd(
          0xff, _mm256_loadu_si256(reinterpret_cast<const __m256i*>(&b.sum[first])));
      const __m256 add = _mm512_maskz_cvtpd_ps(0xff, _mm512_mul_pd(sum, scale));
      float* const to = &beta[static_cast<std::size_t>(first)];
      _mm256_mask_storeu_ps(to, lanes, _mm256_add_ps(_mm256_loadu_ps(to), add));
    }
  }
}
#endif

}  // namespace

void FreeTraversal::addEvidence(const Block& block, double inverse_scale,
                                std::array<float, block::kVoxels>& beta, block::BlockMask& known,
                                bool lanes) {
#ifdef DENSEMAP_EVIDENCE_LANES
  if (lanes && hasWideLanes()) {
    addEvidenceWide(block, inverse_scale, beta, known);
    return;
  }
#endif
  (void)lanes;
  block::forEachSetBit(block.mask, [&](int cell) {
    const auto c = static_cast<std::size_t>(cell);
    beta[c] += static_cast<float>(static_cast<double>(block.sum[c]) * inverse_scale);
    block::setBit(known, cell);
  });
}

struct FreeTraversal::Buffers {
  tbb::enumerable_thread_specific<ThreadBlocks> threads;
};

FreeTraversal::FreeTraversal() : buffers_(std::make_unique<Buffers>()) {}
FreeTraversal::~FreeTraversal() = default;

std::size_t FreeTraversal::memoryBytes() const {
  std::size_t bytes = merged_.capacity() * sizeof(Block*);
  for (const ThreadBlocks& t : buffers_->threads) {
    bytes += t.slots.size() * sizeof(Block) + t.near.capacity() * sizeof(Near) +
             t.index.capacity() * sizeof(t.index[0]);
  }
  return bytes;
}

void FreeTraversal::release() {
  std::vector<const Block*>().swap(merged_);
  buffers_->threads.clear();
}

double FreeTraversal::evidenceShare(double reach) {
  if (!(reach < 1.0)) return 1.0;
  // Midpoint rule on k(x) x over [0, 1]: 10^4 steps, within 1e-6 of the integral.
  constexpr int kSteps = 10000;
  double inside = 0.0, all = 0.0;
  for (int s = 0; s < kSteps; ++s) {
    const double x = (s + 0.5) / kSteps;
    const double v = sparseKernel(x) * x;
    all += v;
    if (x < reach) inside += v;
  }
  return inside / all;
}

double FreeTraversal::scaleFor(double total_weight) {
  // Every visit adds at most weight * scale + 0.5 (the rounding): keep a unit of margin per
  // extent's rounding by halving once more than the bound needs.
  constexpr double kLimit = 2147483647.0;
  double scale = kMaxScale;
  while (scale > 1.0 && 2.0 * total_weight * scale >= kLimit) scale *= 0.5;
  return scale;
}

std::size_t FreeTraversal::accumulate(const VoxelGrid& grid, std::span<const FreeExtent> extents,
                                      double reach) {
  for (ThreadBlocks& t : buffers_->threads) t.reset();
  const SquaredKernelTable& table = squaredKernel();
  reach = std::clamp(reach, 1e-3, 1.0);
  const double compensation = 1.0 / evidenceShare(reach);
  // The rounding margin: a unit per extent of weight (holes, of none, round nothing).
  double total_weight = 0.0, weighted = 0.0;
  for (const FreeExtent& e : extents) {
    total_weight += e.weight * compensation;
    weighted += e.weight > 0.0 ? 1.0 : 0.0;
  }
  scale_ = scaleFor(total_weight + weighted);
  const double scale = scale_;
  std::atomic<std::size_t> visits{0};
  tbb::parallel_for(tbb::blocked_range<std::size_t>(0, extents.size(), 512),
                    [&](const tbb::blocked_range<std::size_t>& range) {
                      ThreadBlocks& mine = buffers_->threads.local();
                      std::size_t n = 0;
                      for (std::size_t r = range.begin(); r != range.end(); ++r) {
                        const FreeExtent& e = extents[r];
                        const Eigen::Vector3d seg = e.to - e.from;
                        if (!(seg.squaredNorm() > 0.0)) continue;
                        const double scaled_weight = e.weight * compensation * scale;
                        const double radius = reach * e.radius_m;
                        int ax = 0;
                        seg.cwiseAbs().maxCoeff(&ax);
                        n += ax == 0   ? rasterise<0>(grid, e, radius, scaled_weight, table, mine)
                             : ax == 1 ? rasterise<1>(grid, e, radius, scaled_weight, table, mine)
                                       : rasterise<2>(grid, e, radius, scaled_weight, table, mine);
                      }
                      visits += n;
                    });
  // Merge: every thread's blocks by key (ascending), each key's sums added into its first
  // block (integer sums: exact in any order; no copy of the blocks).
  std::vector<Block*> all;
  for (ThreadBlocks& t : buffers_->threads) {
    for (std::size_t s = 0; s < t.used; ++s) all.push_back(&t.slots[s]);
  }
  std::sort(all.begin(), all.end(), [](const Block* x, const Block* y) { return x->key < y->key; });
  merged_.clear();
  for (std::size_t i = 0; i < all.size();) {
    Block& m = *all[i];
    merged_.push_back(&m);
    for (++i; i < all.size() && all[i]->key == m.key; ++i) {
      for (int c = 0; c < block::kVoxels; ++c)
        m.sum[static_cast<std::size_t>(c)] += all[i]->sum[static_cast<std::size_t>(c)];
      for (int w = 0; w < block::kMaskWords; ++w)
        m.mask[static_cast<std::size_t>(w)] |= all[i]->mask[static_cast<std::size_t>(w)];
    }
  }
  return visits.load();
}

}  // namespace densemap::kernel
