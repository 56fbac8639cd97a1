#include <algorithm>

#include "densemap/io/file_bytes.hpp"
#include "densemap/io/scan_source.hpp"

namespace densemap {
namespace {

/// la3dm scenes: `<scene>_<n>.pcd`, sorted by n (then by name).
std::vector<std::filesystem::path> listPcds(const std::filesystem::path& dir) {
  std::vector<std::filesystem::path> files;
  std::error_code ec;
  for (const auto& e : std::filesystem::directory_iterator(dir, ec)) {
    if (e.path().extension() == ".pcd") files.push_back(e.path());
  }
  auto number = [](const std::filesystem::path& p) {
    const std::string stem = p.stem().string();
    const auto digits = stem.find_last_not_of("0123456789");
    const std::string tail = stem.substr(digits == std::string::npos ? 0 : digits + 1);
    return tail.empty() ? -1L : std::stol(tail);
  };
  std::sort(files.begin(), files.end(), [&](const auto& a, const auto& b) {
    return std::pair(number(a), a.string()) < std::pair(number(b), b.string());
  });
  return files;
}

class PcdDirectory final : public ScanSource {
 public:
  PcdDirectory(std::vector<std::filesystem::path> files, std::string description)
      : files_(std::move(files)), description_(std::move(description)) {}
  [[nodiscard]] std::size_t size() const override { return files_.size(); }
  [[nodiscard]] std::string describe() const override { return description_; }
  [[nodiscard]] Expected<Scan> load(std::size_t index) const override {
    if (index >= files_.size()) return makeError("scan index out of range");
    auto scan = readPcd(files_[index]);
    if (scan) scan->id = index;
    return scan;
  }

 private:
  std::vector<std::filesystem::path> files_;
  std::string description_;
};

}  // namespace

Expected<std::unique_ptr<ScanSource>> openPcdDirectory(const std::filesystem::path& dir) {
  auto files = listPcds(dir);
  if (files.empty()) return fileError(dir, "no .pcd files");
  const std::string description =
      "PCD directory " + dir.string() + " (" + std::to_string(files.size()) + " scans)";
  return std::make_unique<PcdDirectory>(std::move(files), description);
}

}  // namespace densemap
