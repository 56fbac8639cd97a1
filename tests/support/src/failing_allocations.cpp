#include "densemap/test_support/failing_allocations.hpp"

#include <atomic>
#include <cstdlib>
#include <new>
#include <thread>

namespace densemap::test {
namespace {

std::atomic<std::size_t> g_min_bytes{0};  // 0: disarmed
std::atomic<std::uint64_t> g_left{0};
std::atomic<std::uint64_t> g_failed{0};
std::thread::id g_exempt;  // default (no thread): every thread fails

bool shouldFail(std::size_t size) {
  const std::size_t min_bytes = g_min_bytes.load(std::memory_order_acquire);
  if (min_bytes == 0 || size < min_bytes || std::this_thread::get_id() == g_exempt) return false;
  std::uint64_t left = g_left.load();
  while (left > 0) {
    if (g_left.compare_exchange_weak(left, left - 1)) {
      g_failed.fetch_add(1);
      return true;
    }
  }
  return false;
}

}  // namespace

FailingAllocations::FailingAllocations(std::size_t min_bytes, std::uint64_t count,
                                       Threads threads) {
  g_exempt = threads == kOtherThreads ? std::this_thread::get_id() : std::thread::id();
  g_failed.store(0);
  g_left.store(count);
  g_min_bytes.store(min_bytes == 0 ? 1 : min_bytes, std::memory_order_release);
}

FailingAllocations::~FailingAllocations() { g_min_bytes.store(0, std::memory_order_release); }

std::uint64_t FailingAllocations::failed() const { return g_failed.load(); }

}  // namespace densemap::test

// The replaceable global allocation functions (the array and nothrow forms call these).
void* operator new(std::size_t size) {
  if (densemap::test::shouldFail(size)) throw std::bad_alloc();
  if (void* p = std::malloc(size == 0 ? 1 : size)) return p;
  throw std::bad_alloc();
}

void operator delete(void* p) noexcept { std::free(p); }
void operator delete(void* p, std::size_t) noexcept { std::free(p); }
