// Names off the wire: a discovered publication's topic name (any bytes) against a namespace glob
// and a cloud topic, as ros2.robot_pattern sees them. A namespace found must give back the topic
// it came from; the glob must end (its backtracking is bounded by the lengths).
#include <string>

#include "densemap/ros2/names.hpp"
#include "fuzz_input.hpp"

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  densemap::fuzz::Reader in(data, size);
  const std::uint8_t split = in.take<std::uint8_t>();
  const std::string rest(reinterpret_cast<const char*>(in.rest()), in.restSize());
  const std::size_t cut = rest.empty() ? 0 : split % (rest.size() + 1);
  const std::string pattern = rest.substr(0, cut), topic = rest.substr(cut);
  for (const char* cloud : {"/points", "points", "velodyne/points"}) {
    const std::string ns = densemap::ros2::namespaceOfCloud(topic, cloud);
    if (!ns.empty() && "rt" + densemap::ros2::inNamespace(ns, cloud) != topic) __builtin_trap();
  }
  (void)densemap::ros2::matchesGlob(pattern, topic);
  (void)densemap::ros2::matchesGlob("/robot*", topic);
  (void)densemap::ros2::inNamespace(pattern, topic);
  return 0;
}
