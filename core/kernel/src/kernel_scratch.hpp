#pragma once

#include <cstdint>
#include <utility>
#include <vector>

#include "densemap/kernel/kernel_map.hpp"
#include "free_bundles.hpp"
#include "free_traversal.hpp"
#include "kernel_fit.hpp"
#include "radix_sort.hpp"
#include "sample_index.hpp"

namespace densemap::kernel {

using detail::Kernel;
using detail::SampleIndex;

/// Gives a buffer's memory back (to the allocator, for the next stage's buffers).
template <class T>
void release(std::vector<T>& v) {
  std::vector<T>().swap(v);
}

/// A scan's buffers. Each is released when the stage that needs it ends (releaseSamples,
/// releaseBundles, releaseKernels, releaseFree, FreeTraversal::release), so that the allocator
/// hands the same memory to the next stage's buffers: a scan's peak is its largest stage, not
/// the sum of all its buffers, and between scans the map holds its evidence. Keeping them
/// between scans would spare a few page faults but take more memory and, in the server,
/// more faults in all.
///
struct KernelMap::Scratch {
  std::vector<std::vector<Sample>> sample_parts;
  SampleIndex::Storage index;
  std::vector<Kernel> kernels;
  std::vector<FreeExtent> free_extents;
  std::vector<std::pair<std::uint64_t, std::uint32_t>> pairs;  // (block rank, kernel)
  BlockRanks block_ranks;
  std::vector<std::size_t> pair_offsets;
  std::vector<std::pair<std::uint64_t, std::uint32_t>> pairs_other;
  std::vector<std::uint32_t> radix_counts;
  std::vector<BlockEntry*> targets;  // the entries an accumulation writes evidence to
  FreeBundleBuffers bundles;
  /// The hit kernels' tables (hit_stencil_steps; sharedHitStencils, not owned), set on the
  /// first scan that needs them.
  const detail::HitStencils* hit_stencils = nullptr;

  /// After the kernels are fitted: the samples' chunks and index.
  void releaseSamples() {
    for (auto& part : sample_parts) release(part);
    release(index.starts);
    release(index.entries);
    release(index.bucket);
    release(index.keys);
    release(index.keys_other);
    release(index.counts);
  }
  /// After the free extents are made: the bundles' arrays.
  void releaseBundles() {
    release(bundles.hit_of);
    release(bundles.takes);
    release(bundles.rays);
    release(bundles.rays_other);
    release(bundles.radix_counts);
    release(bundles.group_starts);
    release(bundles.ends);
    release(bundles.counts);
    release(bundles.level_starts);
  }
  /// After the kernels are summed: the kernels and their (block, kernel) pairs.
  void releaseKernels() {
    release(kernels);
    release(pairs);
    release(pairs_other);
    release(pair_offsets);
    release(radix_counts);
  }
  /// After the free evidence is applied: the extents.
  void releaseFree() {
    release(free_extents);
    release(targets);
  }
};

}  // namespace densemap::kernel
