#pragma once

#include <cstdint>
#include <filesystem>
#include <memory>
#include <optional>
#include <string>

#include "densemap/geometry/error.hpp"

namespace densemap {

/// A text file's lines, read a chunk at a time (a `.bz2` file decompressed as it is read):
/// memory holds one chunk and one line, whatever the file's size. Errors (never exceptions)
/// name the file and the reason: missing, unreadable, not a regular file, corrupt bzip2 data,
/// a NUL byte (not text), or a line longer than `max_line_bytes`.
class TextLines {
 public:
  [[nodiscard]] static Expected<TextLines> open(const std::filesystem::path& path,
                                                std::size_t max_line_bytes = 1 << 16);
  TextLines(TextLines&&) noexcept;
  TextLines& operator=(TextLines&&) noexcept;
  ~TextLines();

  /// The next line without its end ('\n', and a '\r' before it), or none at the end of the
  /// file.
  [[nodiscard]] Expected<std::optional<std::string>> next();
  /// Lines returned so far.
  [[nodiscard]] std::uint64_t lineNumber() const;
  [[nodiscard]] const std::filesystem::path& path() const;

 private:
  struct Impl;
  explicit TextLines(std::unique_ptr<Impl> impl);
  std::unique_ptr<Impl> impl_;
};

}  // namespace densemap
