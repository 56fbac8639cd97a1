#pragma once

#include <filesystem>
#include <string>

#include "densemap/geometry/error.hpp"

namespace densemap {

/// The whole file; a `.bz2` file is decompressed. Errors name the file and the reason.
[[nodiscard]] Expected<std::string> readFileBytes(const std::filesystem::path& path);

/// Writes `bytes` to `path` atomically: a temporary file beside it, fsync, rename.
[[nodiscard]] Expected<void> writeFileAtomically(const std::filesystem::path& path,
                                                 const std::string& bytes);

/// "path: message" — the prefix every io error carries.
[[nodiscard]] inline std::unexpected<Error> fileError(const std::filesystem::path& path,
                                                      const std::string& message) {
  return makeError(path.string() + ": " + message);
}

}  // namespace densemap
