#include "densemap/server/export_path.hpp"

#include <sys/stat.h>

#include <algorithm>
#include <cerrno>
#include <cstring>
#include <string>

namespace densemap::server {
namespace {

constexpr std::size_t kMaxNameLength = 128;

bool allowedCharacter(char c) {
  return (c >= 'a' && c <= 'z') || (c >= 'A' && c <= 'Z') || (c >= '0' && c <= '9') || c == '.' ||
         c == '_' || c == '-';
}

}  // namespace

std::filesystem::path exportDirectory(const std::filesystem::path& export_dir,
                                      const std::filesystem::path& snapshot_path) {
  if (!export_dir.empty()) return export_dir;
  if (snapshot_path.empty()) return {};
  const std::filesystem::path parent = snapshot_path.parent_path();
  return (parent.empty() ? std::filesystem::path(".") : parent) / "exports";
}

Expected<std::filesystem::path> confineExportPath(const std::filesystem::path& export_dir,
                                                  std::string_view name) {
  if (export_dir.empty()) {
    return makeError(
        "saving to a named file is off: the server has no snapshot.path or snapshot.export_dir");
  }
  if (name.empty() || name.size() > kMaxNameLength) {
    return makeError("save: the file name must be 1-" + std::to_string(kMaxNameLength) +
                     " characters");
  }
  if (name.find('/') != std::string_view::npos) {
    return makeError("save: '" + std::string(name) +
                     "' is a path; give a file name, written into the server's "
                     "snapshot.export_dir");
  }
  if (name.front() == '.' || !std::all_of(name.begin(), name.end(), allowedCharacter)) {
    return makeError(
        "save: file names are letters, digits, '.', '_' and '-', not starting with "
        "'.'");
  }
  const std::filesystem::path file(name);
  const std::string ext = file.extension().string();
  if (ext != ".dmap" && ext != ".bt" && ext != ".ot") {
    return makeError("save: the file name must end in .dmap, .bt or .ot");
  }
  struct stat st {};
  if (::lstat(export_dir.c_str(), &st) != 0) {
    if (errno != ENOENT || ::mkdir(export_dir.c_str(), 0750) != 0) {
      return makeError("save: export directory " + export_dir.string() + ": " +
                       std::strerror(errno));
    }
  } else if (!S_ISDIR(st.st_mode)) {
    return makeError("save: export directory " + export_dir.string() +
                     " is not a directory (links are not followed)");
  }
  return export_dir / file;
}

}  // namespace densemap::server
