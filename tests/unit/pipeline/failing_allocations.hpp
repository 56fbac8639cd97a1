#pragma once

#include <cstddef>
#include <cstdint>

namespace densemap::test {

/// While one lives, the next `count` allocations of at least `min_bytes` made through the
/// global operator new by any thread other than the one that made it throw std::bad_alloc
/// (failing_allocations.cpp replaces operator new in the test binary that links it). For
/// tests of how a worker thread survives running out of memory.
class FailingAllocations {
 public:
  FailingAllocations(std::size_t min_bytes, std::uint64_t count);
  ~FailingAllocations();
  FailingAllocations(const FailingAllocations&) = delete;
  FailingAllocations& operator=(const FailingAllocations&) = delete;

  /// How many allocations have failed so far.
  [[nodiscard]] std::uint64_t failed() const;
};

}  // namespace densemap::test
