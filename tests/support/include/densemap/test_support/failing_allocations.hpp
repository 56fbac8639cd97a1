#pragma once

#include <cstddef>
#include <cstdint>

namespace densemap::test {

/// While one lives, the next `count` allocations of at least `min_bytes` made through the
/// global operator new throw std::bad_alloc: by any thread other than the one that made it
/// (kOtherThreads), or by every thread. failing_allocations.cpp replaces operator new in each
/// test binary that uses this. For tests of code that must survive running out of memory.
class FailingAllocations {
 public:
  enum Threads { kOtherThreads, kEveryThread };
  FailingAllocations(std::size_t min_bytes, std::uint64_t count,
                     Threads threads = kOtherThreads);
  ~FailingAllocations();
  FailingAllocations(const FailingAllocations&) = delete;
  FailingAllocations& operator=(const FailingAllocations&) = delete;

  /// How many allocations have failed so far.
  [[nodiscard]] std::uint64_t failed() const;
};

}  // namespace densemap::test
