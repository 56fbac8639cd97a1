#include "densemap/ros2/names.hpp"

#include <algorithm>
#include <cctype>

namespace densemap::ros2 {

std::string ddsTopicName(std::string_view ros_name) {
  if (ros_name.empty() || ros_name.back() == '/') return {};
  for (char c : ros_name) {
    if (std::isalnum(static_cast<unsigned char>(c)) == 0 && c != '_' && c != '/') return {};
  }
  if (ros_name.find("//") != std::string_view::npos) return {};
  return ros_name.front() == '/' ? "rt" + std::string(ros_name) : "rt/" + std::string(ros_name);
}

std::string inNamespace(std::string_view ns, std::string_view name) {
  while (!name.empty() && name.front() == '/') name.remove_prefix(1);
  std::string base(ns);
  if (!base.empty() && base.front() != '/') base.insert(base.begin(), '/');
  if (base == "/") base.clear();
  if (!base.empty() && ddsTopicName(base).empty()) return {};
  std::string full = base + "/" + std::string(name);
  return ddsTopicName(full).empty() ? std::string() : full;
}

bool matchesGlob(std::string_view pattern, std::string_view name) {
  // Iterative wildcard matching: on a mismatch, the last '*' takes one more character.
  std::size_t p = 0, n = 0, star = std::string_view::npos, resume = 0;
  while (n < name.size()) {
    if (p < pattern.size() && (pattern[p] == '?' || pattern[p] == name[n])) {
      ++p;
      ++n;
    } else if (p < pattern.size() && pattern[p] == '*') {
      star = p++;
      resume = n;
    } else if (star != std::string_view::npos) {
      p = star + 1;
      n = ++resume;
    } else {
      return false;
    }
  }
  while (p < pattern.size() && pattern[p] == '*') ++p;
  return p == pattern.size();
}

std::string namespaceOfCloud(std::string_view dds_topic, std::string_view cloud) {
  while (!cloud.empty() && cloud.front() == '/') cloud.remove_prefix(1);
  if (cloud.empty() || !dds_topic.starts_with("rt/")) return {};
  const std::string_view name = dds_topic.substr(2);  // "/robot1/points"
  const std::string suffix = "/" + std::string(cloud);
  if (name.size() <= suffix.size() + 1 || !name.ends_with(suffix)) return {};
  std::string ns(name.substr(0, name.size() - suffix.size()));
  return inNamespace(ns, "tf").empty() ? std::string() : ns;
}

bool isNodeName(std::string_view name) {
  if (name.empty() || name.size() > 255) return false;
  if (std::isdigit(static_cast<unsigned char>(name.front())) != 0) return false;
  return std::all_of(name.begin(), name.end(), [](char c) {
    return std::isalnum(static_cast<unsigned char>(c)) != 0 || c == '_';
  });
}

}  // namespace densemap::ros2
