#include "huge_pages.hpp"

#include <sys/mman.h>

#include <cstdint>

namespace densemap {
namespace {

std::size_t roundUp(std::size_t bytes) { return (bytes + kHugePage - 1) & ~(kHugePage - 1); }

}  // namespace

void* mapHugePages(std::size_t bytes) {
  if (bytes == 0 || bytes > SIZE_MAX / 2 - kHugePage) return nullptr;
  const std::size_t size = roundUp(bytes);
  // A huge page's worth more than asked, so that a boundary falls inside; the unused head and
  // tail are unmapped again.
  void* p =
      mmap(nullptr, size + kHugePage, PROT_READ | PROT_WRITE, MAP_PRIVATE | MAP_ANONYMOUS, -1, 0);
  if (p == MAP_FAILED) return nullptr;
  const auto raw = reinterpret_cast<std::uintptr_t>(p);
  const std::uintptr_t start = (raw + kHugePage - 1) & ~(std::uintptr_t{kHugePage} - 1);
  if (start != raw) munmap(p, start - raw);
  const std::uintptr_t tail = raw + size + kHugePage - (start + size);
  if (tail != 0) munmap(reinterpret_cast<void*>(start + size), tail);
  // Advice only: where the kernel has no huge page (or THP is off) the pages stay 4 KiB.
  (void)madvise(reinterpret_cast<void*>(start), size, MADV_HUGEPAGE);
  return reinterpret_cast<void*>(start);
}

void unmapHugePages(void* p, std::size_t bytes) {
  if (p != nullptr) munmap(p, roundUp(bytes));
}

}  // namespace densemap
