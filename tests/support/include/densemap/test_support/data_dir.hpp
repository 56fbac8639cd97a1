#pragma once

#include <filesystem>
#include <optional>
#include <string>

namespace densemap::test {

/// `$DENSEMAP_DATA_DIR/<relative>` (default `../shared/data` beside the project) if it exists.
[[nodiscard]] std::optional<std::filesystem::path> sharedData(const std::string& relative);

/// A fresh empty directory under the system temp dir, removed by the destructor.
class TempDir {
 public:
  TempDir();
  ~TempDir();
  TempDir(const TempDir&) = delete;
  TempDir& operator=(const TempDir&) = delete;
  [[nodiscard]] const std::filesystem::path& path() const { return path_; }

 private:
  std::filesystem::path path_;
};

}  // namespace densemap::test

/// Skips the current test, saying which shared data is missing.
#define DENSEMAP_REQUIRE_DATA(var, relative)                         \
  const auto var##_opt = ::densemap::test::sharedData(relative);     \
  if (!var##_opt)                                                    \
    GTEST_SKIP() << "shared data '" << (relative)                    \
                 << "' not found (set DENSEMAP_DATA_DIR); skipping"; \
  const std::filesystem::path var = *var##_opt
