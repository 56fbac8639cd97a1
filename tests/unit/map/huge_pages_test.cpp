#include "huge_pages.hpp"

#include <gtest/gtest.h>

#include <cstdint>
#include <cstring>
#include <vector>

namespace densemap {
namespace {

TEST(HugePages, ZeroedWritableAndOnAHugePageBoundary) {
  EXPECT_EQ(mapHugePages(0), nullptr);
  // Sizes below, at and past a boundary; several mappings at once (each its own boundary).
  const std::vector<std::size_t> sizes{1, 4096, kHugePage - 1, kHugePage, 3 * kHugePage + 5};
  std::vector<void*> held;
  for (const std::size_t bytes : sizes) {
    void* p = mapHugePages(bytes);
    ASSERT_NE(p, nullptr) << bytes;
    EXPECT_EQ(reinterpret_cast<std::uintptr_t>(p) % kHugePage, 0U) << bytes;
    auto* b = static_cast<unsigned char*>(p);
    std::vector<unsigned char> zeros(bytes, 0);
    EXPECT_EQ(std::memcmp(b, zeros.data(), bytes), 0) << bytes;
    std::memset(b, 0xa5, bytes);  // the whole length is mapped and writable
    EXPECT_EQ(b[bytes - 1], 0xa5);
    held.push_back(p);
  }
  for (std::size_t i = 0; i < held.size(); ++i) unmapHugePages(held[i], sizes[i]);
  // Unmapped and mapped again: zeroed again.
  void* again = mapHugePages(kHugePage);
  ASSERT_NE(again, nullptr);
  EXPECT_EQ(static_cast<unsigned char*>(again)[kHugePage / 2], 0);
  unmapHugePages(again, kHugePage);
}

}  // namespace
}  // namespace densemap
