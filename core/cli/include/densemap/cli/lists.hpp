#pragma once

#include <charconv>
#include <expected>
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

/// A comma-separated list of unsigned numbers and inclusive ranges A..B ("1..40,101"); an item
/// that is not wholly a number or a range is an error naming it.
[[nodiscard]] inline std::expected<std::vector<unsigned>, std::string> parseNumberList(
    const std::string& list) {
  const auto number = [](std::string_view text, unsigned& value) {
    const auto [end, ec] = std::from_chars(text.data(), text.data() + text.size(), value);
    return ec == std::errc() && end == text.data() + text.size() && !text.empty();
  };
  std::vector<unsigned> out;
  for (const std::string& item : splitList(list)) {
    const std::size_t dots = item.find("..");
    unsigned first = 0, last = 0;
    const bool ok = dots == std::string::npos
                        ? number(item, first) && number(item, last)
                        : number(std::string_view(item).substr(0, dots), first) &&
                              number(std::string_view(item).substr(dots + 2), last) &&
                              first <= last && last - first < 100000;
    if (!ok) return std::unexpected("'" + item + "' is not a number or a range A..B");
    for (unsigned v = first; v <= last && v >= first; ++v) {
      out.push_back(v);
      if (v == last) break;
    }
  }
  return out;
}

}  // namespace densemap::tools
