#pragma once

// zlib's CRC-32 over any number of bytes (zlib takes at most a uInt at a time), for the files
// the store writes: snapshots and scan records.
#include <zlib.h>

#include <algorithm>
#include <cstddef>
#include <cstdint>

namespace densemap {

/// CRC-32 of `size` bytes at `data`, continuing `crc` (0 to start).
[[nodiscard]] inline std::uint32_t crc32Of(const void* data, std::size_t size,
                                           std::uint32_t crc = 0) {
  uLong c = crc;
  const auto* p = static_cast<const Bytef*>(data);
  while (size > 0) {
    const auto chunk = static_cast<uInt>(std::min<std::size_t>(size, std::size_t{1} << 30));
    c = crc32(c, p, chunk);
    p += chunk;
    size -= chunk;
  }
  return static_cast<std::uint32_t>(c);
}

}  // namespace densemap
