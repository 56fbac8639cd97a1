#include "densemap/test_support/data_dir.hpp"

#include <cstdlib>
#include <random>

namespace densemap::test {

std::optional<std::filesystem::path> sharedData(const std::string& relative) {
  const char* env = std::getenv("DENSEMAP_DATA_DIR");
  const std::filesystem::path root = env != nullptr ? env : "../shared/data";
  std::filesystem::path p = root / relative;
  std::error_code ec;
  if (!std::filesystem::exists(p, ec)) return std::nullopt;
  return p;
}

TempDir::TempDir() {
  std::random_device rd;
  path_ = std::filesystem::temp_directory_path() /
          ("densemap-test-" + std::to_string(rd()) + std::to_string(rd()));
  std::filesystem::create_directories(path_);
}

TempDir::~TempDir() {
  std::error_code ec;
  std::filesystem::remove_all(path_, ec);
}

}  // namespace densemap::test
