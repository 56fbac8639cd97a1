#pragma once

#include <cstddef>

namespace densemap {

/// The size of a transparent huge page on x86-64 (2 MiB).
inline constexpr std::size_t kHugePage = std::size_t{1} << 21;

/// Zeroed anonymous memory for `bytes`, starting on a huge page's boundary, its length rounded
/// up to whole huge pages and marked for transparent huge pages (madvise): the block store's
/// slabs, which the apply writes at random (with 4 KiB pages nearly every block's node missed
/// the TLB). Not for memory a scan touches sparsely (the dense marks): a huge page is faulted
/// in and zeroed 2 MiB at a time. Null when out of memory or when `bytes` is 0; freed by
/// unmapHugePages with the same `bytes`.
[[nodiscard]] void* mapHugePages(std::size_t bytes);
void unmapHugePages(void* p, std::size_t bytes);

}  // namespace densemap
