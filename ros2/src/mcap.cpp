#include "densemap/ros2/mcap.hpp"

#include <lz4frame.h>
#include <zlib.h>
#include <zstd.h>

#include <cstdio>
#include <cstring>
#include <string_view>

#include "densemap/io/file_bytes.hpp"

namespace densemap::ros2 {
namespace {

constexpr std::string_view kMagic{"\x89MCAP0\r\n", 8};
enum Op : std::uint8_t {
  kHeader = 0x01,
  kFooter = 0x02,
  kSchema = 0x03,
  kChannel = 0x04,
  kMessage = 0x05,
  kChunk = 0x06,
  kDataEnd = 0x0F,
};
constexpr std::uint64_t kMaxSmallRecord = std::uint64_t{16} << 20;  // schema, channel, header
constexpr std::uint64_t kMessageHeader = 2 + 4 + 8 + 8;

std::uint64_t le(const char* p, int n) {
  std::uint64_t v = 0;
  for (int i = n - 1; i >= 0; --i) v = (v << 8) | static_cast<unsigned char>(p[i]);
  return v;
}

/// Reads a record's fields, each checked against the record's end.
class Fields {
 public:
  explicit Fields(std::string_view s) : s_(s) {}
  Expected<std::uint64_t> uint(int n) {
    if (s_.size() - pos_ < static_cast<std::size_t>(n)) return makeError("a record ends early");
    const std::uint64_t v = le(s_.data() + pos_, n);
    pos_ += static_cast<std::size_t>(n);
    return v;
  }
  Expected<std::string_view> prefixed(int length_bytes) {
    auto n = uint(length_bytes);
    if (!n) return std::unexpected(n.error());
    if (*n > s_.size() - pos_) return makeError("a length runs past its record");
    const std::string_view v = s_.substr(pos_, *n);
    pos_ += *n;
    return v;
  }
  [[nodiscard]] std::size_t position() const { return pos_; }
  [[nodiscard]] std::string_view rest() const { return s_.substr(pos_); }

 private:
  std::string_view s_;
  std::size_t pos_ = 0;
};

#define DENSEMAP_MCAP_TRY(var, expr) \
  auto var = (expr);                 \
  if (!var) return std::unexpected(var.error())

void putUint(std::string& out, std::uint64_t v, int n) {
  for (int i = 0; i < n; ++i) out.push_back(static_cast<char>((v >> (8 * i)) & 0xff));
}
void putString(std::string& out, std::string_view s) {
  putUint(out, s.size(), 4);
  out.append(s);
}
void putRecord(std::string& out, std::uint8_t op, const std::string& content) {
  out.push_back(static_cast<char>(op));
  putUint(out, content.size(), 8);
  out.append(content);
}

std::uint32_t crcOf(std::string_view bytes) {
  uLong crc = crc32(0L, Z_NULL, 0);
  // zlib takes at most 4 GiB a call.
  for (std::size_t at = 0; at < bytes.size(); at += std::size_t{1} << 30) {
    const std::size_t n = std::min(bytes.size() - at, std::size_t{1} << 30);
    crc = crc32(crc, reinterpret_cast<const Bytef*>(bytes.data() + at), static_cast<uInt>(n));
  }
  return static_cast<std::uint32_t>(crc);
}

Expected<std::string> decompress(const std::string& compression, std::string_view in,
                                 std::uint64_t size) {
  if (compression.empty()) {
    if (in.size() != size) return makeError("an uncompressed chunk's size does not match");
    return std::string(in);
  }
  std::string out(size, '\0');
  if (compression == "zstd") {
    const std::size_t n = ZSTD_decompress(out.data(), out.size(), in.data(), in.size());
    if (ZSTD_isError(n) != 0) {
      return makeError(std::string("a zstd chunk does not decompress: ") + ZSTD_getErrorName(n));
    }
    if (n != size) return makeError("a zstd chunk decompresses to another size than it says");
    return out;
  }
  if (compression == "lz4") {
    LZ4F_dctx* ctx = nullptr;
    if (LZ4F_isError(LZ4F_createDecompressionContext(&ctx, LZ4F_VERSION)) != 0) {
      return makeError("lz4: no decompression context");
    }
    std::size_t in_at = 0, out_at = 0, hint = 1;
    while (hint != 0 && in_at < in.size()) {
      std::size_t dst = out.size() - out_at, src = in.size() - in_at;
      hint = LZ4F_decompress(ctx, out.data() + out_at, &dst, in.data() + in_at, &src, nullptr);
      if (LZ4F_isError(hint) != 0) {
        LZ4F_freeDecompressionContext(ctx);
        return makeError(std::string("an lz4 chunk does not decompress: ") +
                         LZ4F_getErrorName(hint));
      }
      in_at += src;
      out_at += dst;
      if (dst == 0 && src == 0) break;  // no progress: output full or input exhausted
    }
    LZ4F_freeDecompressionContext(ctx);
    if (hint != 0 || out_at != size) {
      return makeError("an lz4 chunk decompresses to another size than it says");
    }
    return out;
  }
  return makeError("chunks compressed with '" + compression +
                   "' are not supported (none, zstd, lz4)");
}

}  // namespace

/// The file (read with pread-like calls) or bytes in memory.
struct McapReader::Source {
  std::FILE* file = nullptr;
  std::string memory;
  std::uint64_t size = 0;
  mutable std::mutex mutex;
  ~Source() {
    if (file != nullptr) std::fclose(file);
  }
  Expected<std::string> read(std::uint64_t offset, std::uint64_t n) const {
    if (offset > size || n > size - offset) return makeError("a read past the end");
    if (file == nullptr) return memory.substr(offset, n);
    std::string out(n, '\0');
    std::lock_guard lock(mutex);
    if (fseeko(file, static_cast<off_t>(offset), SEEK_SET) != 0 ||
        std::fread(out.data(), 1, n, file) != n) {
      return makeError("cannot read " + std::to_string(n) + " bytes at " + std::to_string(offset));
    }
    return out;
  }
};

McapReader::~McapReader() = default;

Expected<std::unique_ptr<McapReader>> McapReader::open(const std::filesystem::path& path,
                                                       const McapLimits& limits) {
  std::error_code ec;
  if (!std::filesystem::is_regular_file(path, ec)) return fileError(path, "not a regular file");
  std::unique_ptr<McapReader> r(new McapReader());
  r->source_ = std::make_unique<Source>();
  r->source_->file = std::fopen(path.c_str(), "rb");
  if (r->source_->file == nullptr) return fileError(path, "cannot open");
  r->source_->size = std::filesystem::file_size(path, ec);
  if (ec) return fileError(path, "cannot stat");
  r->limits_ = limits;
  r->name_ = path.string();
  if (auto ok = r->index(); !ok) return fileError(path, ok.error().message);
  return r;
}

Expected<std::unique_ptr<McapReader>> McapReader::fromBytes(std::string bytes,
                                                            const McapLimits& limits) {
  std::unique_ptr<McapReader> r(new McapReader());
  r->source_ = std::make_unique<Source>();
  r->source_->size = bytes.size();
  r->source_->memory = std::move(bytes);
  r->limits_ = limits;
  r->name_ = "(memory)";
  if (auto ok = r->index(); !ok) return std::unexpected(ok.error());
  return r;
}

Expected<void> McapReader::index() {
  const Source& s = *source_;
  DENSEMAP_MCAP_TRY(magic, s.read(0, std::min<std::uint64_t>(s.size, kMagic.size())));
  if (*magic != kMagic) return makeError("not an MCAP file (no MCAP magic at its start)");
  std::uint64_t pos = kMagic.size();
  while (true) {
    if (s.size - pos < 9) {
      truncated_ = pos == s.size ? "ends at byte " + std::to_string(pos) + " without a footer"
                                 : "cut inside a record header at byte " + std::to_string(pos);
      break;
    }
    DENSEMAP_MCAP_TRY(head, s.read(pos, 9));
    const auto op = static_cast<std::uint8_t>((*head)[0]);
    const std::uint64_t length = le(head->data() + 1, 8);
    const std::uint64_t at = pos + 9;
    if (length > s.size - at) {
      truncated_ = "cut inside a record (opcode " + std::to_string(op) + ", " +
                   std::to_string(length) + " bytes) at byte " + std::to_string(pos);
      break;
    }
    pos = at + length;
    if (op == kFooter || op == kDataEnd) break;
    if (op == kSchema || op == kChannel) {
      if (length > kMaxSmallRecord) return makeError("a schema or channel record over 16 MiB");
      DENSEMAP_MCAP_TRY(content, s.read(at, length));
      std::string record;
      record.push_back(static_cast<char>(op));
      putUint(record, length, 8);
      record += *content;
      if (auto ok = indexRecords(record, -1); !ok) return ok;
    } else if (op == kMessage) {
      DENSEMAP_MCAP_TRY(content, s.read(at, std::min(length, kMessageHeader)));
      if (auto ok = addMessage(*content, -1, at, length); !ok) return ok;
    } else if (op == kChunk) {
      if (length > limits_.max_chunk_bytes) {
        return makeError("a chunk of " + std::to_string(length) + " bytes (at most " +
                         std::to_string(limits_.max_chunk_bytes) + ")");
      }
      DENSEMAP_MCAP_TRY(content, s.read(at, length));
      Fields f(*content);
      DENSEMAP_MCAP_TRY(start, f.uint(8));
      DENSEMAP_MCAP_TRY(end, f.uint(8));
      DENSEMAP_MCAP_TRY(size, f.uint(8));
      DENSEMAP_MCAP_TRY(crc, f.uint(4));
      DENSEMAP_MCAP_TRY(compression, f.prefixed(4));
      DENSEMAP_MCAP_TRY(records, f.prefixed(8));
      (void)start;
      (void)end;
      if (*size > limits_.max_chunk_bytes) {
        return makeError("a chunk of " + std::to_string(*size) + " bytes uncompressed (at most " +
                         std::to_string(limits_.max_chunk_bytes) + ")");
      }
      Chunk c{at + (f.position() - records->size()), records->size(), *size,
              static_cast<std::uint32_t>(*crc), std::string(*compression)};
      chunks_.push_back(c);
      DENSEMAP_MCAP_TRY(plain, chunkRecords(c));
      if (auto ok = indexRecords(*plain, static_cast<std::int64_t>(chunks_.size() - 1)); !ok) {
        return std::unexpected(
            Error{"chunk " + std::to_string(chunks_.size()) + ": " + ok.error().message});
      }
    }
  }
  return {};
}

Expected<void> McapReader::addMessage(std::string_view content, std::int64_t chunk,
                                      std::uint64_t at, std::uint64_t length) {
  // channel id (2), sequence (4), log time (8), publish time (8), then the data.
  if (length < kMessageHeader || content.size() < kMessageHeader) {
    return makeError("a message record shorter than its header");
  }
  if (messages_.size() >= limits_.max_messages) return makeError("too many messages");
  if (length - kMessageHeader > limits_.max_message_bytes) {
    return makeError("a message of " + std::to_string(length - kMessageHeader) +
                     " bytes (at most " + std::to_string(limits_.max_message_bytes) + ")");
  }
  messages_.push_back({static_cast<std::uint16_t>(le(content.data(), 2)), le(content.data() + 6, 8),
                       chunk, at + kMessageHeader, length - kMessageHeader});
  return {};
}

Expected<std::string> McapReader::chunkRecords(const Chunk& c) const {
  DENSEMAP_MCAP_TRY(compressed, source_->read(c.records_offset, c.records_length));
  DENSEMAP_MCAP_TRY(plain, decompress(c.compression, *compressed, c.uncompressed_size));
  if (c.crc != 0 && crcOf(*plain) != c.crc) return makeError("a chunk's CRC does not match");
  return plain;
}

Expected<void> McapReader::indexRecords(const std::string& records, std::int64_t chunk) {
  std::uint64_t pos = 0;
  while (pos < records.size()) {
    if (records.size() - pos < 9) return makeError("a record header runs past its chunk");
    const auto op = static_cast<std::uint8_t>(records[pos]);
    const std::uint64_t length = le(records.data() + pos + 1, 8);
    const std::uint64_t at = pos + 9;
    if (length > records.size() - at) return makeError("a record runs past its chunk");
    pos = at + length;
    const std::string_view content(records.data() + at, length);
    Fields f(content);
    if (op == kSchema) {
      DENSEMAP_MCAP_TRY(id, f.uint(2));
      DENSEMAP_MCAP_TRY(name, f.prefixed(4));
      DENSEMAP_MCAP_TRY(encoding, f.prefixed(4));
      DENSEMAP_MCAP_TRY(data, f.prefixed(4));
      (void)data;
      schemas_.push_back(
          {static_cast<std::uint16_t>(*id), {std::string(*name), std::string(*encoding)}});
    } else if (op == kChannel) {
      DENSEMAP_MCAP_TRY(id, f.uint(2));
      DENSEMAP_MCAP_TRY(schema, f.uint(2));
      DENSEMAP_MCAP_TRY(topic, f.prefixed(4));
      DENSEMAP_MCAP_TRY(encoding, f.prefixed(4));
      DENSEMAP_MCAP_TRY(metadata, f.prefixed(4));
      (void)metadata;
      if (channel(static_cast<std::uint16_t>(*id)) != nullptr) continue;  // repeated: same
      if (channels().size() >= limits_.max_channels) return makeError("too many channels");
      BagChannel c;
      c.id = static_cast<std::uint16_t>(*id);
      c.topic = std::string(*topic);
      c.message_encoding = std::string(*encoding);
      for (const auto& [sid, named] : schemas_) {
        if (*schema != 0 && sid == *schema) {
          c.schema_name = named.first;
          c.schema_encoding = named.second;
        }
      }
      addChannel(std::move(c));
    } else if (op == kMessage) {
      if (chunk < 0) continue;  // top-level messages are indexed by index()
      if (auto ok = addMessage(content, chunk, at, length); !ok) return ok;
    }
  }
  return {};
}

Expected<std::string> McapReader::data(const BagMessage& m, std::uint64_t max_bytes) const {
  const std::uint64_t length = std::min(m.length, max_bytes);
  if (m.chunk < 0) return source_->read(m.offset, length);
  if (m.chunk >= static_cast<std::int64_t>(chunks_.size())) return makeError("no such chunk");
  std::lock_guard lock(cache_mutex_);
  if (cached_chunk_ != m.chunk) {
    DENSEMAP_MCAP_TRY(plain, chunkRecords(chunks_[static_cast<std::size_t>(m.chunk)]));
    cached_records_ = std::move(*plain);
    cached_chunk_ = m.chunk;
  }
  if (m.offset > cached_records_.size() || m.length > cached_records_.size() - m.offset) {
    return makeError("a message past its chunk");
  }
  return cached_records_.substr(m.offset, length);
}

Expected<McapCompression> parseMcapCompression(const std::string& name) {
  if (name == "none") return McapCompression::kNone;
  if (name == "zstd") return McapCompression::kZstd;
  if (name == "lz4") return McapCompression::kLz4;
  return makeError("unknown MCAP compression '" + name + "' (none, zstd or lz4)");
}

McapWriter::McapWriter(McapCompression compression, std::size_t chunk_bytes)
    : compression_(compression), chunk_bytes_(chunk_bytes) {
  out_.append(kMagic);
  std::string header;
  putString(header, "ros2");
  putString(header, "densemap");
  putRecord(out_, kHeader, header);
}

std::uint16_t McapWriter::addSchema(const std::string& name, const std::string& encoding,
                                    const std::string& data) {
  std::string r;
  putUint(r, next_schema_, 2);
  putString(r, name);
  putString(r, encoding);
  putString(r, data);
  putRecord(out_, kSchema, r);
  return next_schema_++;
}

std::uint16_t McapWriter::addChannel(std::uint16_t schema, const std::string& topic,
                                     const std::string& message_encoding) {
  std::string r;
  putUint(r, next_channel_, 2);
  putUint(r, schema, 2);
  putString(r, topic);
  putString(r, message_encoding);
  putUint(r, 0, 4);  // no metadata
  putRecord(out_, kChannel, r);
  return next_channel_++;
}

void McapWriter::write(std::uint16_t channel, std::uint64_t log_time, const std::string& data) {
  std::string r;
  putUint(r, channel, 2);
  putUint(r, sequence_++, 4);
  putUint(r, log_time, 8);
  putUint(r, log_time, 8);
  r += data;
  if (chunk_.empty()) chunk_start_ = log_time;
  chunk_start_ = std::min(chunk_start_, log_time);
  chunk_end_ = std::max(chunk_end_, log_time);
  putRecord(chunk_, kMessage, r);
  if (chunk_.size() >= chunk_bytes_) flushChunk();
}

void McapWriter::flushChunk() {
  if (chunk_.empty()) return;
  std::string compressed;
  std::string name;
  if (compression_ == McapCompression::kZstd) {
    name = "zstd";
    compressed.resize(ZSTD_compressBound(chunk_.size()));
    const std::size_t n =
        ZSTD_compress(compressed.data(), compressed.size(), chunk_.data(), chunk_.size(), 3);
    if (ZSTD_isError(n) != 0) error_ = std::string("zstd: ") + ZSTD_getErrorName(n);
    compressed.resize(ZSTD_isError(n) != 0 ? 0 : n);
  } else if (compression_ == McapCompression::kLz4) {
    name = "lz4";
    compressed.resize(LZ4F_compressFrameBound(chunk_.size(), nullptr));
    const std::size_t n = LZ4F_compressFrame(compressed.data(), compressed.size(), chunk_.data(),
                                             chunk_.size(), nullptr);
    if (LZ4F_isError(n) != 0) error_ = std::string("lz4: ") + LZ4F_getErrorName(n);
    compressed.resize(LZ4F_isError(n) != 0 ? 0 : n);
  } else {
    compressed = chunk_;
  }
  std::string r;
  putUint(r, chunk_start_, 8);
  putUint(r, chunk_end_, 8);
  putUint(r, chunk_.size(), 8);
  putUint(r, crcOf(chunk_), 4);
  putString(r, name);
  putUint(r, compressed.size(), 8);
  r += compressed;
  putRecord(out_, kChunk, r);
  chunk_.clear();
  chunk_end_ = 0;
}

Expected<std::string> McapWriter::finish() {
  flushChunk();
  if (!error_.empty()) return makeError(error_);
  std::string data_end;
  putUint(data_end, 0, 4);  // no data section CRC
  putRecord(out_, kDataEnd, data_end);
  std::string footer;
  putUint(footer, 0, 8);  // no summary section
  putUint(footer, 0, 8);
  putUint(footer, 0, 4);
  putRecord(out_, kFooter, footer);
  out_.append(kMagic);
  return std::move(out_);
}

}  // namespace densemap::ros2
