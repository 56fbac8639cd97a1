#pragma once

#include <cstdint>
#include <filesystem>
#include <string>

#include "densemap/geometry/error.hpp"

namespace densemap {

/// The largest file (or decompressed `.bz2` content) readFileBytes reads unless told otherwise.
inline constexpr std::uint64_t kDefaultMaxFileBytes = std::uint64_t{8} << 30;  // 8 GiB

/// The whole file; a `.bz2` file is decompressed. Errors (never exceptions) name the file and
/// the reason: missing, unreadable, a directory or anything but a regular file, larger than
/// `max_bytes`, or decompressing to more than `max_bytes`.
[[nodiscard]] Expected<std::string> readFileBytes(const std::filesystem::path& path,
                                                  std::uint64_t max_bytes = kDefaultMaxFileBytes);

/// Writes `bytes` to `path` atomically: a temporary file of its own beside it (unique per call,
/// so concurrent writers of one path never share it), fsync, rename. `mode`: the new file's
/// permissions (before the umask does not apply: exactly these).
[[nodiscard]] Expected<void> writeFileAtomically(const std::filesystem::path& path,
                                                 const std::string& bytes, unsigned mode = 0644);

/// "path: message" — the prefix every io error carries.
[[nodiscard]] inline std::unexpected<Error> fileError(const std::filesystem::path& path,
                                                      const std::string& message) {
  return makeError(path.string() + ": " + message);
}

}  // namespace densemap
