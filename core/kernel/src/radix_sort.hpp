#pragma once

#include <tbb/parallel_for.h>

#include <algorithm>
#include <cstddef>
#include <cstdint>
#include <vector>

namespace densemap::kernel {

/// Sorts `items` by key(item) (an unsigned integer below 2^key_bits), stably: a least
/// significant digit radix sort, 11 bits a pass, each pass counted and placed in parallel by
/// fixed chunks of the items, so the order never depends on the thread count. `scratch` is a
/// buffer the caller keeps between calls. About 5x faster than a comparison sort of the
/// few hundred thousand (key, index) pairs of a scan (issue 29).
template <class T, class KeyOf>
void radixSort(std::vector<T>& items, std::vector<T>& scratch, int key_bits, KeyOf&& key,
               std::vector<std::uint32_t>& counts) {
  constexpr int kBits = 11;
  constexpr std::size_t kBins = std::size_t{1} << kBits;
  constexpr std::size_t kChunk = 32768;
  const std::size_t n = items.size();
  const std::size_t chunks = (n + kChunk - 1) / kChunk;
  scratch.resize(n);
  for (int shift = 0; shift < key_bits; shift += kBits) {
    const auto digit = [&key, shift](const T& item) {
      return static_cast<std::size_t>((key(item) >> shift) & (kBins - 1));
    };
    counts.assign(chunks * kBins, 0);
    tbb::parallel_for(std::size_t{0}, chunks, [&](std::size_t c) {
      std::uint32_t* mine = counts.data() + c * kBins;
      for (std::size_t i = c * kChunk; i < std::min(n, (c + 1) * kChunk); ++i)
        ++mine[digit(items[i])];
    });
    // Exclusive offsets, digit major, chunk minor: stable.
    std::uint32_t sum = 0;
    for (std::size_t d = 0; d < kBins; ++d) {
      for (std::size_t c = 0; c < chunks; ++c) {
        const std::uint32_t k = counts[c * kBins + d];
        counts[c * kBins + d] = sum;
        sum += k;
      }
    }
    tbb::parallel_for(std::size_t{0}, chunks, [&](std::size_t c) {
      std::uint32_t* mine = counts.data() + c * kBins;
      for (std::size_t i = c * kChunk; i < std::min(n, (c + 1) * kChunk); ++i) {
        scratch[mine[digit(items[i])]++] = items[i];
      }
    });
    items.swap(scratch);
  }
}

}  // namespace densemap::kernel
