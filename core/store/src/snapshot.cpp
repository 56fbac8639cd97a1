#include "densemap/store/snapshot.hpp"

#include <cmath>
#include <cstdio>

#include <zlib.h>

#include <algorithm>
#include <cstring>

#include "densemap/io/file_bytes.hpp"
#include "densemap/io/octomap_export.hpp"
#include "densemap/map/map_factory.hpp"
#include "snapshot.pb.h"

namespace densemap {
namespace {

Expected<std::unique_ptr<OccupancyMap>> toMap(const MapView& view, const SensorModel& model,
                                              Backend backend) {
  auto map = makeMap(backend, view.grid().resolution(), model);
  if (!map) return map;
  view.forEachKnown([&](const VoxelKey& k, float v) { (*map)->setLogOdds(k, v); });
  return map;
}

/// CRC-32 of the keys then the values (zlib's).
std::uint32_t cellsCrc(const std::string& keys, const std::string& values) {
  uLong crc = crc32(0L, Z_NULL, 0);
  for (const std::string* part : {&keys, &values}) {
    const auto* data = reinterpret_cast<const Bytef*>(part->data());
    std::size_t left = part->size();
    while (left > 0) {  // crc32 takes at most a uInt at a time
      const uInt chunk = static_cast<uInt>(std::min<std::size_t>(left, 1U << 30));
      crc = crc32(crc, data, chunk);
      data += chunk;
      left -= chunk;
    }
  }
  return static_cast<std::uint32_t>(crc);
}

}  // namespace

Expected<std::size_t> saveSnapshot(const MapView& view, const SensorModel& model, Backend backend,
                                   const std::filesystem::path& file) {
  const std::string ext = file.extension().string();
  if (ext == ".bt" || ext == ".ot") {
    auto map = toMap(view, model, Backend::kGrid);
    if (!map) return std::unexpected(map.error());
    if (auto ok = exportOctomap(**map, file); !ok) return std::unexpected(ok.error());
    return std::filesystem::file_size(file);
  }
  proto::Snapshot s;
  s.set_format_version(2);  // 2: cells_crc32 is required
  s.set_resolution_m(view.grid().resolution());
  s.set_backend(std::string(backendName(backend)));
  const auto& p = model.probabilities();
  s.mutable_sensor()->set_prob_hit(p.hit);
  s.mutable_sensor()->set_prob_miss(p.miss);
  s.mutable_sensor()->set_clamp_min(p.clamp_min);
  s.mutable_sensor()->set_clamp_max(p.clamp_max);
  s.set_map_version(view.version());
  std::string keys, values;
  keys.reserve(view.knownCells() * 6);
  values.reserve(view.knownCells() * 4);
  std::size_t n = 0;
  view.forEachKnown([&](const VoxelKey& k, float v) {
    const std::uint16_t xyz[3] = {k.x, k.y, k.z};
    keys.append(reinterpret_cast<const char*>(xyz), sizeof(xyz));
    values.append(reinterpret_cast<const char*>(&v), sizeof(v));
    ++n;
  });
  s.set_cell_count(n);
  s.set_cells_crc32(cellsCrc(keys, values));
  s.set_keys(std::move(keys));
  s.set_log_odds(std::move(values));
  std::string bytes;
  if (!s.SerializeToString(&bytes)) return fileError(file, "cannot serialise snapshot");
  if (auto ok = writeFileAtomically(file, bytes); !ok) return std::unexpected(ok.error());
  return bytes.size();
}

Expected<LoadedSnapshot> loadSnapshot(const std::filesystem::path& file, Backend backend,
                                      double expected_resolution_m) {
  auto bytes = readFileBytes(file);
  if (!bytes) return std::unexpected(bytes.error());
  if (bytes->empty()) return fileError(file, "empty file: not a densemap snapshot");
  proto::Snapshot s;
  if (!s.ParseFromString(*bytes))
    return fileError(file, "not a densemap snapshot (corrupt or truncated)");
  if (s.format_version() != 1 && s.format_version() != 2) {
    return fileError(file, "unsupported snapshot format " + std::to_string(s.format_version()));
  }
  const std::size_t n = s.cell_count();
  if (s.keys().size() != n * 6 || s.log_odds().size() != n * 4) {
    return fileError(file, "snapshot arrays do not match its cell count (truncated?)");
  }
  // The CRC is serialised last: a file cut just before it would parse, so version 2 needs it.
  if (s.format_version() == 2 && !s.has_cells_crc32()) {
    return fileError(file, "snapshot lacks its CRC-32 (truncated)");
  }
  if (s.has_cells_crc32() && s.cells_crc32() != cellsCrc(s.keys(), s.log_odds())) {
    return fileError(file, "snapshot cells fail their CRC-32 (corrupt)");
  }
  if (expected_resolution_m > 0 && s.resolution_m() != expected_resolution_m) {
    return fileError(file, "snapshot resolution " + std::to_string(s.resolution_m()) +
                               " m differs from the configured " +
                               std::to_string(expected_resolution_m) + " m");
  }
  const SensorModel model(SensorProbabilities{s.sensor().prob_hit(), s.sensor().prob_miss(),
                                              s.sensor().clamp_min(), s.sensor().clamp_max()});
  auto map = makeMap(backend, s.resolution_m(), model);
  if (!map) return fileError(file, map.error().message);
  for (std::size_t i = 0; i < n; ++i) {
    std::uint16_t xyz[3];
    float v;
    std::memcpy(xyz, s.keys().data() + i * 6, 6);
    std::memcpy(&v, s.log_odds().data() + i * 4, 4);
    (*map)->setLogOdds(VoxelKey{xyz[0], xyz[1], xyz[2]}, v);
  }
  return LoadedSnapshot{std::move(*map), s.map_version()};
}

std::filesystem::path snapshotGeneration(const std::filesystem::path& path, int g) {
  if (g == 0) return path;
  return std::filesystem::path(path.string() + (g < 0 ? ".new" : "." + std::to_string(g)));
}

Expected<std::size_t> saveSnapshotKeeping(const MapView& view, const SensorModel& model,
                                          Backend backend, const std::filesystem::path& path,
                                          int keep) {
  if (keep < 1 || keep > 100) return makeError("snapshot.keep must be 1 .. 100");
  // The extension decides the format: write `path.new` as `path` would be written.
  const std::string ext = path.extension().string();
  if (ext == ".bt" || ext == ".ot") {
    return saveSnapshot(view, model, backend, path);  // OctoMap files: no generations
  }
  const std::filesystem::path fresh = snapshotGeneration(path, -1);
  auto size = saveSnapshot(view, model, backend, fresh);
  if (!size) return size;
  std::error_code ec;
  for (int g = keep - 1; g >= 1; --g) {
    const auto from = snapshotGeneration(path, g - 1);
    if (std::filesystem::exists(from, ec)) {
      std::filesystem::rename(from, snapshotGeneration(path, g), ec);
      if (ec) return fileError(from, "cannot rotate: " + ec.message());
    }
  }
  std::filesystem::rename(fresh, path, ec);
  if (ec) return fileError(fresh, "cannot move into place: " + ec.message());
  return size;
}

Expected<std::optional<ResumedSnapshot>> loadNewestSnapshot(const std::filesystem::path& path,
                                                            int keep, Backend backend,
                                                            double expected_resolution_m) {
  std::vector<std::string> skipped;
  for (int g = -1; g < std::max(keep, 1); ++g) {
    const auto file = snapshotGeneration(path, g);
    std::error_code ec;
    if (!std::filesystem::exists(file, ec)) continue;
    auto loaded = loadSnapshot(file, backend, 0.0);
    // A readable snapshot at another resolution is not corrupt: it is the map, and resuming an
    // older generation instead (or none) would silently lose it. Refused with the way out.
    if (loaded && expected_resolution_m > 0 &&
        std::abs(loaded->map->resolution() - expected_resolution_m) > 1e-12) {
      char text[160];
      std::snprintf(text, sizeof text, "was mapped at %g m but map.resolution_m is %g m",
                    loaded->map->resolution(), expected_resolution_m);
      return fileError(file, std::string(text) +
                                 ": set it back to resume this map, or move the snapshot files "
                                 "aside to start a new one");
    }
    if (loaded) {
      return std::optional<ResumedSnapshot>(
          ResumedSnapshot{std::move(*loaded), file, std::move(skipped)});
    }
    skipped.push_back(loaded.error().message);
  }
  if (skipped.empty()) return std::optional<ResumedSnapshot>();
  std::string all;
  for (const auto& reason : skipped) all += (all.empty() ? "" : "; ") + reason;
  return makeError("no readable snapshot: " + all);
}

}  // namespace densemap
