#pragma once

#include <cstddef>

namespace densemap {

/// The size of a transparent huge page on x86-64 (2 MiB).
inline constexpr std::size_t kHugePage = std::size_t{1} << 21;

/// Zeroed anonymous memory for `bytes`, starting on a huge page's boundary, its length rounded
/// up to whole huge pages and marked for transparent huge pages (madvise): the dense marks'
/// and the block store's memory is read and written at random, and with 4 KiB pages nearly
/// every block's access missed the TLB. Pages never touched stay unmapped. Null when out of
/// memory or when `bytes` is 0; freed by unmapHugePages with the same `bytes`.
[[nodiscard]] void* mapHugePages(std::size_t bytes);
void unmapHugePages(void* p, std::size_t bytes);

}  // namespace densemap
