#pragma once

#include <malloc.h>
#include <unistd.h>

#include <algorithm>
#include <cstddef>
#include <cstdlib>
#include <fstream>
#include <string>
#include <string_view>

namespace densemap::cli {

/// Scans, their world-frame copies and a dense map's stage buffers are megabytes each, every
/// scan: blocks up to 64 MiB come from the heap, for reuse, instead of a fresh mapping each (a
/// page fault per 4 KiB, every scan; docs/benchmarks.md), and free memory at a heap's top goes
/// back to the system only beyond `trim_threshold_bytes`.
inline void keepScanBuffersInHeap(std::size_t trim_threshold_bytes) {
  mallopt(M_MMAP_THRESHOLD, 64 << 20);
  mallopt(M_TRIM_THRESHOLD, static_cast<int>(trim_threshold_bytes));
}

/// A dense map's stages take and give back tens of MiB each, every scan. Beyond the trim
/// threshold a heap gives its free top back to the system, and the next stage faults those
/// pages in again; a heap keeps `keep_bytes` of free top instead (M_TOP_PAD: a trim returns
/// only what lies beyond it, so a larger burst, a point-query flood's, still goes back).
/// At most 1 GiB.
inline void keepStageBuffersInHeap(std::size_t keep_bytes) {
  mallopt(M_TOP_PAD, static_cast<int>(std::min(keep_bytes, std::size_t{1} << 30)));
}

/// densemap-server's heap, before any thread starts (a dense map then adds
/// keepStageBuffersInHeap). Free memory at the top of a heap beyond 32 MiB goes back to the
/// system: a thread's heap gives its top back only past this threshold (malloc_trim does not
/// trim it), so a larger one leaves a point-query flood's memory behind. Two heaps for all
/// threads (glibc makes up to 8 per core): fewer thread heaps to hold freed memory after
/// point-query floods; integration at 10 Hz does not need more.
inline void serverHeap() {
  keepScanBuffersInHeap(std::size_t{32} << 20);
  mallopt(M_ARENA_MAX, 2);
}

/// How the process's heap is paged (heapOnHugePages).
enum class HeapPages {
  kHuge,          // glibc.malloc.hugetlb=1: the heap on transparent huge pages
  kOptedOut,      // DENSEMAP_MALLOC=default
  kKernelOff,     // the kernel's transparent huge pages are off (or unknown)
  kTunableSet,    // GLIBC_TUNABLES names glibc.malloc.hugetlb with another value
  kRestartFailed  // the restart with the tunable failed: 4 KiB pages
};

/// A line for the log: how the heap is paged, and how to change it.
[[nodiscard]] inline const char* describe(HeapPages pages) {
  switch (pages) {
    case HeapPages::kHuge:
      return "heap on transparent huge pages (glibc.malloc.hugetlb=1; DENSEMAP_MALLOC=default "
             "turns them off)";
    case HeapPages::kOptedOut:
      return "heap on 4 KiB pages (DENSEMAP_MALLOC=default)";
    case HeapPages::kKernelOff:
      return "heap on 4 KiB pages: the kernel's transparent huge pages are off "
             "(/sys/kernel/mm/transparent_hugepage/enabled)";
    case HeapPages::kTunableSet:
      return "heap as GLIBC_TUNABLES sets glibc.malloc.hugetlb";
    case HeapPages::kRestartFailed:
      return "heap on 4 KiB pages: restarting with glibc.malloc.hugetlb=1 failed";
  }
  return "heap: unknown";
}

/// Puts the heap on transparent huge pages: a dense map's scan buffers are tens of MiB, taken
/// and given back every scan, and on 4 KiB pages the kernel faults them in anew, thousands of
/// times a second (docs/benchmarks.md). glibc reads
/// its `glibc.malloc.hugetlb` tunable only at start-up, so the first call adds it to
/// GLIBC_TUNABLES and starts the program again (execv of /proc/self/exe with the same
/// arguments, same process); the second finds it set. Call first thing in main, before any
/// thread starts. Left as they are: DENSEMAP_MALLOC=default, a kernel whose transparent huge
/// pages are "never", and a GLIBC_TUNABLES that already names the tunable.
[[nodiscard]] inline HeapPages heapOnHugePages(char** argv) {
  constexpr std::string_view kTunable = "glibc.malloc.hugetlb=";
  if (const char* choice = std::getenv("DENSEMAP_MALLOC");
      choice != nullptr && std::string_view(choice) == "default") {
    return HeapPages::kOptedOut;
  }
  const char* tunables = std::getenv("GLIBC_TUNABLES");
  const std::string current = tunables != nullptr ? tunables : "";
  if (const std::size_t at = current.find(kTunable); at != std::string::npos) {
    const std::string_view value = std::string_view(current).substr(at + kTunable.size(), 1);
    return value == "1" ? HeapPages::kHuge : HeapPages::kTunableSet;
  }
  std::ifstream mode("/sys/kernel/mm/transparent_hugepage/enabled");
  std::string line;
  if (!std::getline(mode, line) || line.find("[never]") != std::string::npos) {
    return HeapPages::kKernelOff;
  }
  const std::string with =
      current.empty() ? std::string(kTunable) + "1" : current + ":" + std::string(kTunable) + "1";
  if (setenv("GLIBC_TUNABLES", with.c_str(), 1) != 0) return HeapPages::kRestartFailed;
  execv("/proc/self/exe", argv);
  // Still here: the restart failed; the environment goes back as it was.
  if (tunables != nullptr) {
    setenv("GLIBC_TUNABLES", current.c_str(), 1);
  } else {
    unsetenv("GLIBC_TUNABLES");
  }
  return HeapPages::kRestartFailed;
}

}  // namespace densemap::cli
