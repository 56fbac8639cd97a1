#pragma once

#include <sstream>
#include <string>
#include <vector>

namespace densemap::tools {

/// The non-empty items of a comma-separated command-line list.
[[nodiscard]] inline std::vector<std::string> splitList(const std::string& list) {
  std::vector<std::string> out;
  std::stringstream ss(list);
  for (std::string item; std::getline(ss, item, ',');) {
    if (!item.empty()) out.push_back(item);
  }
  return out;
}

}  // namespace densemap::tools
