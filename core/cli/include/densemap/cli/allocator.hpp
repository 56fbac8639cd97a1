#pragma once

#include <malloc.h>

#include <cstddef>

namespace densemap::cli {

/// Scans, their world-frame copies and a dense map's stage buffers are megabytes each, every
/// scan: blocks up to 64 MiB come from the heap, for reuse, instead of a fresh mapping each (a
/// page fault per 4 KiB, every scan; docs/benchmarks.md), and free memory at a heap's top goes
/// back to the system only beyond `trim_threshold_bytes`.
inline void keepScanBuffersInHeap(std::size_t trim_threshold_bytes) {
  mallopt(M_MMAP_THRESHOLD, 64 << 20);
  mallopt(M_TRIM_THRESHOLD, static_cast<int>(trim_threshold_bytes));
}

}  // namespace densemap::cli
