#pragma once

// rosbag2's SQLite storage (`.db3`, Humble's default): tables `topics` (id, name, type,
// serialization_format) and `messages` (id, topic_id, timestamp, data), read with Debian's
// libsqlite3 (read-only; a corrupt database is SQLite's error, never a crash), written for the
// bags densemap makes.
#include <filesystem>
#include <memory>
#include <string>
#include <vector>

#include "densemap/geometry/error.hpp"
#include "densemap/ros2/bag_reader.hpp"

namespace densemap::ros2 {

class Db3Reader final : public BagReader {
 public:
  [[nodiscard]] static Expected<std::unique_ptr<Db3Reader>> open(
      const std::filesystem::path& path, std::size_t max_messages = 10'000'000);
  ~Db3Reader() override;
  [[nodiscard]] Expected<std::string> data(const BagMessage& m,
                                           std::uint64_t max_bytes = ~std::uint64_t{
                                               0}) const override;
  [[nodiscard]] std::string kind() const override { return "rosbag2 SQLite bag"; }

 private:
  struct Db;
  Db3Reader();
  std::unique_ptr<Db> db_;
};

/// One topic of a bag being written: its name and type (CDR messages).
struct Db3Topic {
  std::string name, type;
};
struct Db3Row {
  std::size_t topic = 0;  // index into the topics
  std::int64_t timestamp = 0;
  std::string data;
};
/// Writes a rosbag2 SQLite bag (a new file; an existing one is refused).
[[nodiscard]] Expected<void> writeDb3(const std::filesystem::path& path,
                                      const std::vector<Db3Topic>& topics,
                                      const std::vector<Db3Row>& rows);

}  // namespace densemap::ros2
