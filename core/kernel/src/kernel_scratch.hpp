#pragma once

#include <cstdint>
#include <utility>
#include <vector>

#include "densemap/kernel/kernel_map.hpp"
#include "free_bundles.hpp"
#include "free_traversal.hpp"
#include "kernel_fit.hpp"
#include "sample_index.hpp"

namespace densemap::kernel {

using detail::Kernel;
using detail::SampleIndex;

/// A scan's buffers, kept between scans: a fresh vector per scan costs a page fault per 4 KiB
/// (about 6% of a BALM scan's time was the kernel's fault handler).
struct KernelMap::Scratch {
  std::vector<std::vector<Sample>> sample_parts;
  SampleIndex::Storage index;
  std::vector<Kernel> kernels;
  std::vector<FreeExtent> free_extents;
  std::vector<std::pair<std::uint64_t, std::uint32_t>> pairs;
  std::vector<std::size_t> pair_offsets;
  std::vector<std::pair<std::uint64_t, std::uint32_t>> pairs_other;
  std::vector<std::uint32_t> radix_counts;
  std::vector<Block*> free_targets;
  FreeBundleBuffers bundles;
};

}  // namespace densemap::kernel
