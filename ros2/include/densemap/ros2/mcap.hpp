#pragma once

// MCAP (mcap.dev, the format rosbag2 records by default since Iron), read and written from the
// published specification: the records of the data section, messages at top level or in
// chunks (uncompressed, zstd or lz4 frames). Untrusted input: every length is checked against
// what is left and against the limits below before anything is allocated.
#include <cstdint>
#include <filesystem>
#include <memory>
#include <mutex>
#include <string>
#include <string_view>
#include <vector>

#include "densemap/geometry/error.hpp"
#include "densemap/ros2/bag_reader.hpp"

namespace densemap::ros2 {

struct McapLimits {
  std::uint64_t max_chunk_bytes = std::uint64_t{512} << 20;  // a chunk, compressed or not
  std::uint64_t max_message_bytes = std::uint64_t{1} << 30;  // one message's data
  std::size_t max_messages = 10'000'000;
  std::size_t max_channels = 4096;
};

/// The index of an MCAP file's data section (its summary section is not needed and not read).
/// A file cut short (a recorder that died) keeps the messages before the cut (truncated() says
/// where); anything else malformed is refused at open.
class McapReader final : public BagReader {
 public:
  [[nodiscard]] static Expected<std::unique_ptr<McapReader>> open(const std::filesystem::path& path,
                                                                  const McapLimits& limits = {});
  /// The same over bytes in memory (tests, fuzzing).
  [[nodiscard]] static Expected<std::unique_ptr<McapReader>> fromBytes(
      std::string bytes, const McapLimits& limits = {});
  ~McapReader();

  /// A message's data (the last chunk read is kept).
  [[nodiscard]] Expected<std::string> data(const BagMessage& m,
                                           std::uint64_t max_bytes = ~std::uint64_t{
                                               0}) const override;
  [[nodiscard]] std::string kind() const override { return "MCAP bag"; }

 private:
  struct Source;
  struct Chunk {
    std::uint64_t records_offset = 0, records_length = 0, uncompressed_size = 0;
    std::uint32_t crc = 0;
    std::string compression;
  };
  McapReader() = default;
  Expected<void> index();
  Expected<void> indexRecords(const std::string& records, std::int64_t chunk);
  Expected<std::string> chunkRecords(const Chunk& c) const;
  /// Indexes the message record of `length` bytes at `at` (in the file, or in `chunk`'s
  /// records) whose content starts with `content` (its header at least).
  Expected<void> addMessage(std::string_view content, std::int64_t chunk, std::uint64_t at,
                            std::uint64_t length);

  std::unique_ptr<Source> source_;
  McapLimits limits_;
  std::vector<std::pair<std::uint16_t, std::pair<std::string, std::string>>> schemas_;
  std::vector<Chunk> chunks_;
  mutable std::mutex cache_mutex_;
  mutable std::int64_t cached_chunk_ = -1;
  mutable std::string cached_records_;
};

enum class McapCompression { kNone, kZstd, kLz4 };

/// Writes an MCAP file (profile "ros2"): schemas, channels, then messages in chunks of about
/// `chunk_bytes` (compressed as asked), a data end and a footer; no summary section.
class McapWriter {
 public:
  explicit McapWriter(McapCompression compression, std::size_t chunk_bytes = std::size_t{1} << 20);
  std::uint16_t addSchema(const std::string& name, const std::string& encoding,
                          const std::string& data);
  std::uint16_t addChannel(std::uint16_t schema, const std::string& topic,
                           const std::string& message_encoding);
  void write(std::uint16_t channel, std::uint64_t log_time, const std::string& data);
  /// The whole file's bytes; the writer is spent.
  [[nodiscard]] Expected<std::string> finish();

 private:
  void flushChunk();
  McapCompression compression_;
  std::size_t chunk_bytes_;
  std::string out_, chunk_;
  std::uint64_t chunk_start_ = 0, chunk_end_ = 0;
  std::uint16_t next_schema_ = 1, next_channel_ = 0;
  std::uint32_t sequence_ = 0;
  std::string error_;
};

/// "none", "zstd", "lz4".
[[nodiscard]] Expected<McapCompression> parseMcapCompression(const std::string& name);

}  // namespace densemap::ros2
