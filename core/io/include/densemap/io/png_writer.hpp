#pragma once

#include <cstdint>
#include <filesystem>
#include <vector>

#include "densemap/geometry/error.hpp"

namespace densemap {

/// Writes an 8-bit RGB image (row-major, 3 bytes per pixel) as a PNG file.
[[nodiscard]] Expected<void> writePng(const std::filesystem::path& file, int width, int height,
                                      const std::vector<std::uint8_t>& rgb);

}  // namespace densemap
