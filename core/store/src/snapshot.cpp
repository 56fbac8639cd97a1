#include "densemap/store/snapshot.hpp"

#include <cstring>

#include "snapshot.pb.h"
#include "densemap/io/file_bytes.hpp"
#include "densemap/io/octomap_export.hpp"
#include "densemap/map/map_factory.hpp"

namespace densemap {
namespace {

Expected<std::unique_ptr<OccupancyMap>> toMap(const MapView& view, const SensorModel& model,
                                              Backend backend) {
  auto map = makeMap(backend, view.grid().resolution(), model);
  if (!map) return map;
  view.forEachKnown([&](const VoxelKey& k, float v) { (*map)->setLogOdds(k, v); });
  return map;
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
  s.set_format_version(1);
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
  proto::Snapshot s;
  if (!s.ParseFromString(*bytes))
    return fileError(file, "not a densemap snapshot (corrupt or truncated)");
  if (s.format_version() != 1) {
    return fileError(file, "unsupported snapshot format " + std::to_string(s.format_version()));
  }
  const std::size_t n = s.cell_count();
  if (s.keys().size() != n * 6 || s.log_odds().size() != n * 4) {
    return fileError(file, "snapshot arrays do not match its cell count (truncated?)");
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

}  // namespace densemap
