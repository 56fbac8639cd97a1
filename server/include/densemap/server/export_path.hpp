#pragma once

#include <filesystem>
#include <string_view>

#include "densemap/geometry/error.hpp"

namespace densemap::server {

/// The directory named saves go to: `export_dir` when set, else `exports/` beside
/// `snapshot_path`; empty when neither is configured (named saves are then refused).
[[nodiscard]] std::filesystem::path exportDirectory(const std::filesystem::path& export_dir,
                                                    const std::filesystem::path& snapshot_path);

/// Where a `save` request that names `name` may write (docs/security.md: no request may name a
/// path outside the directory the operator configured). `name` must be a plain file name: 1-128
/// characters of [A-Za-z0-9._-], not starting with '.', ending in .dmap, .bt or .ot; no '/',
/// so no `..`, no absolute path and no other directory. The file goes into `export_dir`, which
/// is created (0750) if missing; a symlink or non-directory there is refused. Writes replace the
/// directory entry by rename, so a link planted under the name is replaced, never followed.
[[nodiscard]] Expected<std::filesystem::path> confineExportPath(
    const std::filesystem::path& export_dir, std::string_view name);

}  // namespace densemap::server
