#include "densemap/kernel/kernel_map.hpp"

#include <algorithm>
#include <bit>
#include <cmath>
#include <limits>
#include <utility>

#include "block_logits.hpp"
#include "kernel_scratch.hpp"

/// The kernel map as a store: its cells' evidence, probabilities, erasure and eviction,
/// snapshots' evidence, memory.
namespace densemap::kernel {

const BlockEvidence* KernelMap::find(std::uint64_t block_key) const {
  const BlockEntry* e = std::as_const(*store_).findEntry(block_key);
  return e != nullptr ? e->evidence.get() : nullptr;
}

template <typename F>
void KernelMap::forEachBlock(F&& f) const {
  std::vector<std::pair<std::uint64_t, const BlockEvidence*>> order;
  order.reserve(store_->evidenceBlocks());
  store_->forEachEntryWriter([&](const BlockEntry& e) {
    if (e.evidence) order.emplace_back(e.key, e.evidence.get());
  });
  std::sort(order.begin(), order.end());  // a file does not depend on the store's order
  for (const auto& [block_key, b] : order) f(block_key, *b);
}

void KernelMap::erase(const VoxelKey& key) {
  BlockEntry* e = store_->findEntry(block::blockOf(key));
  if (e == nullptr || !e->evidence) return;
  BlockEvidence& b = *e->evidence;
  const int cell = block::indexOf(key);
  block::clearBit(b.known, cell);
  b.alpha[cell] = 0.0F;
  b.beta[cell] = 0.0F;
  // A block with no cell left goes (the published map drops it too; eviction follows it).
  if (block::countBits(b.known) == 0) store_->dropEvidence(*e);
}

std::size_t KernelMap::evictBlocks(const std::function<bool(const Point3f&)>& keep) {
  std::size_t dropped = 0;
  store_->forEachEntryWriter([&](BlockEntry& e) {
    if (e.evidence && !keep(block::centreOf(grid_, e.key))) {
      store_->dropEvidence(e);
      ++dropped;
    }
  });
  return dropped;
}

std::optional<double> KernelMap::probability(const VoxelKey& key) const {
  const BlockEvidence* b = find(block::blockOf(key));
  const int cell = block::indexOf(key);
  if (b == nullptr || !block::testBit(b->known, cell)) return std::nullopt;
  const double alpha = options_.prior + b->alpha[cell];
  const double beta = options_.prior + b->beta[cell];
  return alpha / (alpha + beta);
}

void KernelMap::blockLogOdds(std::uint64_t block_key, const block::BlockMask& cells,
                             std::array<float, block::kVoxels>& log_odds) const {
  const BlockEvidence* b = find(block_key);
  if (b == nullptr) {  // every cell unknown: p = 0.5
    block::forEachSetBit(cells, [&](int cell) { log_odds[cell] = 0.0F; });
    return;
  }
  blockLogits(b->alpha, b->beta, b->known, cells, options_.prior, log_odds);
}

void KernelMap::forEachKnown(const std::function<void(const VoxelKey&, double)>& f) const {
  forEachBlock([&](std::uint64_t block_key, const BlockEvidence& b) {
    block::forEachSetBit(b.known, [&](int cell) {
      const double alpha = options_.prior + b.alpha[cell];
      const double beta = options_.prior + b.beta[cell];
      f(block::keyOf(block_key, cell), alpha / (alpha + beta));
    });
  });
}

KernelEvidence KernelMap::evidence() const {
  KernelEvidence e;
  e.method = options_.method;
  e.resolution_m = grid_.resolution();
  e.scans = scans_;
  const std::size_t n = knownCells();
  e.keys.reserve(n);
  e.alpha.reserve(n);
  e.beta.reserve(n);
  forEachBlock([&](std::uint64_t block_key, const BlockEvidence& b) {
    block::forEachSetBit(b.known, [&](int cell) {
      e.keys.push_back(block::keyOf(block_key, cell));
      e.alpha.push_back(b.alpha[static_cast<std::size_t>(cell)]);
      e.beta.push_back(b.beta[static_cast<std::size_t>(cell)]);
    });
  });
  return e;
}

Expected<void> KernelMap::restore(const KernelEvidence& e) {
  if (e.method != options_.method) {
    return makeError("kernel evidence of " + std::string(kernelMethodName(e.method)) + ", not " +
                     std::string(kernelMethodName(options_.method)));
  }
  if (e.resolution_m != grid_.resolution()) {
    return makeError("kernel evidence at " + std::to_string(e.resolution_m) + " m, not " +
                     std::to_string(grid_.resolution()) + " m");
  }
  if (e.alpha.size() != e.keys.size() || e.beta.size() != e.keys.size()) {
    return makeError("kernel evidence arrays differ in length");
  }
  // Held as float: a value beyond float's range is refused, not stored as infinity.
  const auto valid = [](double v) {
    return std::isfinite(v) && v >= 0.0 && v <= std::numeric_limits<float>::max();
  };
  for (std::size_t i = 0; i < e.keys.size(); ++i) {
    if (!valid(e.alpha[i]) || !valid(e.beta[i])) {
      return makeError("kernel evidence has a negative or non-finite value");
    }
  }
  store_->forEachEntryWriter([&](BlockEntry& entry) { store_->dropEvidence(entry); });
  for (std::size_t i = 0; i < e.keys.size(); ++i) {
    BlockEvidence& b = store_->evidence(store_->entry(block::blockOf(e.keys[i])));
    const int cell = block::indexOf(e.keys[i]);
    b.alpha[static_cast<std::size_t>(cell)] = static_cast<float>(e.alpha[i]);
    b.beta[static_cast<std::size_t>(cell)] = static_cast<float>(e.beta[i]);
    block::setBit(b.known, cell);
  }
  scans_ = e.scans;
  return {};
}

std::size_t KernelMap::memoryBytes() const {
  std::size_t bytes = own_store_ ? own_store_->memoryBytes() : 0;
  bytes += scratch_->targets.capacity() * sizeof(BlockEntry*);
  bytes += (samples_.capacity() + segments_.capacity()) * sizeof(Sample);
  for (const auto& part : scratch_->sample_parts) bytes += part.capacity() * sizeof(Sample);
  bytes += scratch_->index.starts.capacity() * sizeof(std::uint32_t) +
           scratch_->index.entries.capacity() * sizeof(SampleIndex::Entry) +
           scratch_->index.bucket.capacity() * sizeof(std::uint32_t) +
           (scratch_->index.keys.capacity() + scratch_->index.keys_other.capacity()) *
               sizeof(std::uint64_t) +
           scratch_->index.counts.capacity() * sizeof(std::uint32_t);
  const FreeBundleBuffers& fb = scratch_->bundles;
  bytes += (fb.hit_of.capacity() + fb.takes.capacity()) * sizeof(std::uint32_t) +
           (fb.rays.capacity() + fb.rays_other.capacity()) *
               sizeof(std::pair<std::uint64_t, std::uint32_t>) +
           fb.radix_counts.capacity() * sizeof(std::uint32_t) +
           fb.group_starts.capacity() * sizeof(std::size_t);
  bytes += scratch_->kernels.capacity() * sizeof(Kernel) +
           scratch_->free_extents.capacity() * sizeof(FreeExtent) +
           (scratch_->pairs.capacity() + scratch_->pairs_other.capacity()) *
               sizeof(std::pair<std::uint64_t, std::uint32_t>) +
           scratch_->radix_counts.capacity() * sizeof(std::uint32_t);
  return bytes + free_->memoryBytes();
}

std::size_t KernelMap::knownCells() const {
  std::size_t n = 0;
  store_->forEachEntryWriter([&](const BlockEntry& e) {
    if (e.evidence) n += block::countBits(e.evidence->known);
  });
  return n;
}

}  // namespace densemap::kernel
