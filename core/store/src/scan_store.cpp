#include "densemap/store/scan_store.hpp"

#include <fcntl.h>
#include <unistd.h>
#include <zlib.h>

#include <algorithm>
#include <atomic>
#include <bit>
#include <cerrno>
#include <cstring>
#include <system_error>

#include "crc.hpp"

namespace densemap {

static_assert(std::endian::native == std::endian::little, "records are little-endian");

namespace {

constexpr std::uint32_t kRecordMagic = 0x52534D44;  // "DMSR"
constexpr std::size_t kHeaderBytes = 16;

void put(std::vector<std::uint8_t>& out, const void* data, std::size_t n) {
  const auto* p = static_cast<const std::uint8_t*>(data);
  out.insert(out.end(), p, p + n);
}

template <class T>
void putValue(std::vector<std::uint8_t>& out, const T& value) {
  put(out, &value, sizeof(T));
}

/// Reads fixed-size fields off a decoded payload, refusing to read past its end.
class Reader {
 public:
  explicit Reader(std::span<const std::uint8_t> bytes) : bytes_(bytes) {}
  template <class T>
  bool get(T& value) {
    if (bytes_.size() - at_ < sizeof(T)) return false;
    std::memcpy(&value, bytes_.data() + at_, sizeof(T));
    at_ += sizeof(T);
    return true;
  }
  [[nodiscard]] std::size_t left() const { return bytes_.size() - at_; }
  [[nodiscard]] const std::uint8_t* here() const { return bytes_.data() + at_; }
  void skip(std::size_t n) { at_ += n; }

 private:
  std::span<const std::uint8_t> bytes_;
  std::size_t at_ = 0;
};

std::string errnoText() { return std::system_category().message(errno); }

}  // namespace

std::vector<std::uint8_t> encodeScanRecord(const RawScan& scan) {
  std::vector<std::uint8_t> raw;
  const std::size_t floats = scan.xyz.size() + scan.intensity.size();
  raw.reserve(96 + scan.sensor_id.size() + floats * sizeof(float));
  putValue(raw, static_cast<std::uint32_t>(scan.sensor_id.size()));
  put(raw, scan.sensor_id.data(), scan.sensor_id.size());
  putValue(raw, scan.seq);
  putValue(raw, scan.stamp_ns);
  putValue(raw, scan.t_world_sensor);
  putValue(raw, scan.q_world_sensor);
  putValue(raw, static_cast<std::uint32_t>(scan.xyz.size()));
  putValue(raw, static_cast<std::uint32_t>(scan.intensity.size()));
  // The floats' bytes by plane (every float's first byte, then every second...): neighbouring
  // points share signs and exponents, which zlib then finds as runs.
  const std::size_t start = raw.size();
  raw.resize(start + floats * sizeof(float));
  std::size_t i = 0;
  for (const auto* array : {&scan.xyz, &scan.intensity}) {
    for (const float f : *array) {
      std::uint8_t b[4];
      std::memcpy(b, &f, 4);
      for (std::size_t plane = 0; plane < 4; ++plane) raw[start + plane * floats + i] = b[plane];
      ++i;
    }
  }
  uLongf packed_size = compressBound(static_cast<uLong>(raw.size()));
  std::vector<std::uint8_t> out(kHeaderBytes + packed_size);
  if (compress2(out.data() + kHeaderBytes, &packed_size, raw.data(), static_cast<uLong>(raw.size()),
                Z_BEST_SPEED) != Z_OK) {
    return {};
  }
  out.resize(kHeaderBytes + packed_size);
  const std::uint32_t header[4] = {kRecordMagic, static_cast<std::uint32_t>(packed_size),
                                   static_cast<std::uint32_t>(raw.size()),
                                   crc32Of(out.data() + kHeaderBytes, packed_size)};
  std::memcpy(out.data(), header, kHeaderBytes);
  return out;
}

Expected<RawScan> decodeScanRecord(std::span<const std::uint8_t> bytes) {
  if (bytes.size() < kHeaderBytes) return makeError("scan record: shorter than its header");
  std::uint32_t header[4];
  std::memcpy(header, bytes.data(), kHeaderBytes);
  const auto [magic, packed_size, raw_size, crc] = header;
  if (magic != kRecordMagic) return makeError("scan record: not a scan record (magic)");
  if (packed_size != bytes.size() - kHeaderBytes) {
    return makeError("scan record: its length says " + std::to_string(packed_size) +
                     " compressed bytes, the record holds " +
                     std::to_string(bytes.size() - kHeaderBytes));
  }
  if (raw_size > kMaxScanRecordBytes) {
    return makeError("scan record: decodes to " + std::to_string(raw_size) +
                     " bytes, more than a scan may hold");
  }
  if (crc32Of(bytes.data() + kHeaderBytes, packed_size) != crc) {
    return makeError("scan record: damaged (CRC)");
  }
  std::vector<std::uint8_t> raw(raw_size);
  uLongf got = raw_size;
  if (uncompress(raw.data(), &got, bytes.data() + kHeaderBytes, packed_size) != Z_OK ||
      got != raw_size) {
    return makeError("scan record: damaged (does not decompress to its length)");
  }
  Reader in(raw);
  RawScan scan;
  std::uint32_t id_size = 0, n_xyz = 0, n_intensity = 0;
  if (!in.get(id_size) || id_size > in.left()) return makeError("scan record: truncated id");
  scan.sensor_id.assign(reinterpret_cast<const char*>(in.here()), id_size);
  in.skip(id_size);
  if (!in.get(scan.seq) || !in.get(scan.stamp_ns) || !in.get(scan.t_world_sensor) ||
      !in.get(scan.q_world_sensor) || !in.get(n_xyz) || !in.get(n_intensity)) {
    return makeError("scan record: truncated header fields");
  }
  const std::uint64_t floats = std::uint64_t{n_xyz} + n_intensity;
  if (n_xyz % 3 != 0 || (n_intensity != 0 && n_intensity * std::uint64_t{3} != n_xyz) ||
      floats * sizeof(float) != in.left()) {
    return makeError("scan record: its point and intensity counts do not match its size");
  }
  scan.xyz.resize(n_xyz);
  scan.intensity.resize(n_intensity);
  const std::uint8_t* planes = in.here();
  std::size_t i = 0;
  for (auto* array : {&scan.xyz, &scan.intensity}) {
    for (float& f : *array) {
      std::uint8_t b[4];
      for (std::size_t plane = 0; plane < 4; ++plane) b[plane] = planes[plane * floats + i];
      std::memcpy(&f, b, 4);
      ++i;
    }
  }
  return scan;
}

/// One segment file, open for appending (the newest) and reading; removed when the last entry
/// that names it is dropped.
struct ScanStore::Segment {
  std::filesystem::path path;
  int fd = -1;
  std::uint64_t size = 0;
  ~Segment() {
    if (fd >= 0) ::close(fd);
    std::error_code ignored;
    std::filesystem::remove(path, ignored);
  }
};

Expected<std::unique_ptr<ScanStore>> ScanStore::create(const ScanStoreOptions& options) {
  if (options.directory.empty()) return makeError("scan store: no directory");
  if (options.max_bytes == 0 || options.segment_bytes == 0) {
    return makeError("scan store: max_bytes and segment_bytes must be positive");
  }
  std::error_code ec;
  std::filesystem::create_directories(options.directory, ec);
  if (ec) return makeError("scan store: " + options.directory.string() + ": " + ec.message());
  static std::atomic<int> stores{0};
  const auto dir = options.directory / ("densemap-scans-" + std::to_string(::getpid()) + "-" +
                                        std::to_string(stores.fetch_add(1)));
  std::filesystem::remove_all(dir, ec);  // a dead process's files under the same pid
  if (!std::filesystem::create_directory(dir, ec) || ec) {
    return makeError("scan store: cannot make " + dir.string() + ": " +
                     (ec ? ec.message() : "exists"));
  }
  return std::unique_ptr<ScanStore>(new ScanStore(options, dir));
}

ScanStore::ScanStore(const ScanStoreOptions& options, std::filesystem::path directory)
    : options_(options), directory_(std::move(directory)) {}

ScanStore::~ScanStore() {
  entries_.clear();
  segments_.clear();
  std::error_code ignored;
  std::filesystem::remove_all(directory_, ignored);
}

Expected<std::uint64_t> ScanStore::append(const RawScan& scan) {
  const std::vector<std::uint8_t> record = encodeScanRecord(scan);
  if (record.empty()) return makeError("scan store: cannot compress a scan");
  const std::lock_guard lock(mutex_);
  if (bytes_ + record.size() > options_.max_bytes) {
    return makeError("scan store: full (" + std::to_string(bytes_) + " of " +
                     std::to_string(options_.max_bytes) + " bytes)");
  }
  if (segments_.empty() || segments_.back()->size + record.size() > options_.segment_bytes) {
    auto segment = std::make_shared<Segment>();
    segment->path = directory_ / ("segment-" + std::to_string(first_ + entries_.size()));
    segment->fd = ::open(segment->path.c_str(), O_RDWR | O_CREAT | O_EXCL | O_CLOEXEC, 0600);
    if (segment->fd < 0) {
      return makeError("scan store: " + segment->path.string() + ": " + errnoText());
    }
    segments_.push_back(std::move(segment));
  }
  Segment& segment = *segments_.back();
  std::size_t written = 0;
  while (written < record.size()) {
    const ssize_t n = ::pwrite(segment.fd, record.data() + written, record.size() - written,
                               static_cast<off_t>(segment.size + written));
    if (n < 0 && errno == EINTR) continue;
    if (n <= 0) return makeError("scan store: " + segment.path.string() + ": " + errnoText());
    written += static_cast<std::size_t>(n);
  }
  const std::uint64_t index = first_ + entries_.size();
  entries_.push_back({segments_.back(), segment.size, static_cast<std::uint32_t>(record.size()),
                      scan.sensor_id, scan.stamp_ns, scan.t_world_sensor, scan.q_world_sensor});
  segment.size += record.size();
  bytes_ += record.size();
  by_stamp_[scan.sensor_id][scan.stamp_ns] = index;
  return index;
}

const ScanStore::Entry* ScanStore::entry(std::uint64_t index) const {
  if (index < first_ || index - first_ >= entries_.size()) return nullptr;
  return &entries_[index - first_];
}

Expected<RawScan> ScanStore::read(std::uint64_t index) const {
  std::shared_ptr<Segment> segment;
  std::uint64_t offset = 0;
  std::uint32_t length = 0;
  std::array<double, 3> t{};
  std::array<double, 4> q{};
  {
    const std::lock_guard lock(mutex_);
    const Entry* e = entry(index);
    if (e == nullptr) return makeError("scan store: scan " + std::to_string(index) + " not kept");
    segment = e->segment;
    offset = e->offset;
    length = e->length;
    t = e->t;
    q = e->q;
  }
  std::vector<std::uint8_t> bytes(length);
  std::size_t got = 0;
  while (got < length) {
    const ssize_t n =
        ::pread(segment->fd, bytes.data() + got, length - got, static_cast<off_t>(offset + got));
    if (n < 0 && errno == EINTR) continue;
    if (n <= 0) {
      return makeError("scan store: " + segment->path.string() + ": " +
                       (n == 0 ? std::string("truncated") : errnoText()));
    }
    got += static_cast<std::size_t>(n);
  }
  auto scan = decodeScanRecord(bytes);
  if (!scan) return makeError(segment->path.string() + ": " + scan.error().message);
  scan->t_world_sensor = t;
  scan->q_world_sensor = q;
  return scan;
}

std::optional<std::uint64_t> ScanStore::find(std::string_view sensor_id,
                                             std::int64_t stamp_ns) const {
  const std::lock_guard lock(mutex_);
  const auto sensor = by_stamp_.find(std::string(sensor_id));
  if (sensor == by_stamp_.end()) return std::nullopt;
  const auto it = sensor->second.find(stamp_ns);
  if (it == sensor->second.end() || it->second < first_) return std::nullopt;
  return it->second;
}

bool ScanStore::setPose(std::uint64_t index, const std::array<double, 3>& t,
                        const std::array<double, 4>& q) {
  const std::lock_guard lock(mutex_);
  if (index < first_ || index - first_ >= entries_.size()) return false;
  entries_[index - first_].t = t;
  entries_[index - first_].q = q;
  return true;
}

void ScanStore::dropBefore(std::uint64_t index) {
  const std::lock_guard lock(mutex_);
  index = std::min(index, first_ + entries_.size());
  if (index <= first_) return;
  const std::size_t n = index - first_;
  for (std::size_t i = 0; i < n; ++i) {
    const Entry& e = entries_[i];
    auto sensor = by_stamp_.find(e.sensor_id);
    if (sensor != by_stamp_.end()) {
      auto it = sensor->second.find(e.stamp_ns);
      if (it != sensor->second.end() && it->second == first_ + i) sensor->second.erase(it);
      if (sensor->second.empty()) by_stamp_.erase(sensor);
    }
  }
  entries_.erase(entries_.begin(), entries_.begin() + static_cast<std::ptrdiff_t>(n));
  first_ = index;
  // A segment whose scans are all dropped goes (its file with it, once no read holds it); with
  // none kept, so does the one being written (the next append starts a new one).
  const Segment* oldest_kept = entries_.empty() ? nullptr : entries_.front().segment.get();
  while (!segments_.empty() && segments_.front().get() != oldest_kept) {
    bytes_ -= segments_.front()->size;
    segments_.erase(segments_.begin());
  }
}

std::uint64_t ScanStore::first() const {
  const std::lock_guard lock(mutex_);
  return first_;
}

std::uint64_t ScanStore::end() const {
  const std::lock_guard lock(mutex_);
  return first_ + entries_.size();
}

std::size_t ScanStore::bytes() const {
  const std::lock_guard lock(mutex_);
  return bytes_;
}

}  // namespace densemap
