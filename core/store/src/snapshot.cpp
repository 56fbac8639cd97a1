#include "densemap/store/snapshot.hpp"

#include <cmath>
#include <cstdio>

#include <zlib.h>

#include <algorithm>
#include <cstring>
#include <initializer_list>

#include "densemap/io/file_bytes.hpp"
#include "densemap/io/octomap_export.hpp"
#include "densemap/map/map_factory.hpp"
#include "crc.hpp"
#include "snapshot.pb.h"

namespace densemap {

Expected<std::unique_ptr<OccupancyMap>> mapOfView(const MapView& view, const SensorModel& model,
                                                  Backend backend) {
  auto map = makeMap(backend, view.grid().resolution(), model);
  if (!map) return map;
  view.forEachKnown([&](const VoxelKey& k, float v) { (*map)->setLogOdds(k, v); });
  return map;
}

namespace {

/// CRC-32 of the parts in order (zlib's): keys then values.
std::uint32_t cellsCrc(std::initializer_list<const std::string*> parts) {
  std::uint32_t crc = 0;
  for (const std::string* part : parts) crc = crc32Of(part->data(), part->size(), crc);
  return crc;
}

template <class T>
void appendRaw(std::string& out, const T& value) {
  out.append(reinterpret_cast<const char*>(&value), sizeof(T));
}

void putKernelEvidence(const kernel::KernelEvidence& e, proto::Snapshot& s) {
  std::string keys, alpha, beta;
  keys.reserve(e.keys.size() * 6);
  alpha.reserve(e.alpha.size() * 8);
  beta.reserve(e.beta.size() * 8);
  for (std::size_t i = 0; i < e.keys.size(); ++i) {
    const std::uint16_t xyz[3] = {e.keys[i].x, e.keys[i].y, e.keys[i].z};
    appendRaw(keys, xyz);
    appendRaw(alpha, e.alpha[i]);
    appendRaw(beta, e.beta[i]);
  }
  s.set_kernel_method(std::string(kernel::kernelMethodName(e.method)));
  s.set_kernel_scans(e.scans);
  s.set_kernel_cell_count(e.keys.size());
  s.set_kernel_crc32(cellsCrc({&keys, &alpha, &beta}));
  s.set_kernel_keys(std::move(keys));
  s.set_kernel_alpha(std::move(alpha));
  s.set_kernel_beta(std::move(beta));
}

/// The kernel evidence of `s`, checked (lengths, CRC, method); std::nullopt when it has none.
Expected<std::optional<kernel::KernelEvidence>> kernelEvidenceOf(const proto::Snapshot& s) {
  if (s.format_version() < 3) return std::optional<kernel::KernelEvidence>();
  if (!s.has_kernel_method()) return makeError("snapshot lacks its kernel evidence (truncated)");
  auto method = kernel::parseKernelMethod(s.kernel_method());
  if (!method) return makeError("snapshot kernel evidence: " + method.error().message);
  const std::uint64_t n = s.kernel_cell_count();
  // Lengths first (no allocation from an unchecked count), then the CRC, serialised last.
  if (n > s.kernel_keys().size() / 6 || s.kernel_keys().size() != n * 6 ||
      s.kernel_alpha().size() != n * 8 || s.kernel_beta().size() != n * 8) {
    return makeError("snapshot kernel evidence arrays do not match its cell count (truncated?)");
  }
  if (!s.has_kernel_crc32() ||
      s.kernel_crc32() != cellsCrc({&s.kernel_keys(), &s.kernel_alpha(), &s.kernel_beta()})) {
    return makeError("snapshot kernel evidence fails its CRC-32 (corrupt or truncated)");
  }
  kernel::KernelEvidence e;
  e.method = *method;
  e.resolution_m = s.resolution_m();
  e.scans = s.kernel_scans();
  e.keys.resize(n);
  e.alpha.resize(n);
  e.beta.resize(n);
  for (std::size_t i = 0; i < n; ++i) {
    std::uint16_t xyz[3];
    std::memcpy(xyz, s.kernel_keys().data() + i * 6, 6);
    e.keys[i] = VoxelKey{xyz[0], xyz[1], xyz[2]};
    std::memcpy(&e.alpha[i], s.kernel_alpha().data() + i * 8, 8);
    std::memcpy(&e.beta[i], s.kernel_beta().data() + i * 8, 8);
    if (!(std::isfinite(e.alpha[i]) && e.alpha[i] >= 0.0 && std::isfinite(e.beta[i]) &&
          e.beta[i] >= 0.0)) {
      return makeError("snapshot kernel evidence has a negative or non-finite value");
    }
  }
  return std::optional<kernel::KernelEvidence>(std::move(e));
}

}  // namespace

Expected<std::size_t> saveSnapshot(const MapView& view, const SensorModel& model, Backend backend,
                                   const std::filesystem::path& file,
                                   const kernel::KernelEvidence* kernel, SnapshotValues kind) {
  const std::string ext = file.extension().string();
  if (ext == ".bt" || ext == ".ot") {
    auto map = mapOfView(view, model, Backend::kGrid);
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
  // The map kind is written last (field 17) and covered by the cells' CRC: a file cut before
  // it fails the CRC like any other cut.
  const std::string map_kind = kernel != nullptr
                                   ? std::string(kernel::kernelMethodName(kernel->method))
                               : kind == SnapshotValues::kLogOdds ? "log_odds"
                                                                  : "unclamped";
  s.set_cells_crc32(cellsCrc({&keys, &values, &map_kind}));
  s.set_keys(std::move(keys));
  s.set_log_odds(std::move(values));
  if (kernel != nullptr) {
    // Format 3: the kernel evidence is required. Fields are written in number order, so a file
    // cut before the evidence's CRC (field 16, last) is refused, never read as a log-odds map.
    s.set_format_version(3);
    putKernelEvidence(*kernel, s);
  }
  s.set_map_kind(map_kind);
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
  if (s.format_version() < 1 || s.format_version() > 3) {
    return fileError(file, "unsupported snapshot format " + std::to_string(s.format_version()));
  }
  const std::size_t n = s.cell_count();
  if (s.keys().size() != n * 6 || s.log_odds().size() != n * 4) {
    return fileError(file, "snapshot arrays do not match its cell count (truncated?)");
  }
  // The CRC is serialised last: a file cut just before it would parse, so version 2 needs it.
  if (s.format_version() >= 2 && !s.has_cells_crc32()) {
    return fileError(file, "snapshot lacks its CRC-32 (truncated)");
  }
  // The kind, when the file has one, is covered by the CRC too.
  const std::string no_kind;
  if (s.has_cells_crc32() &&
      s.cells_crc32() !=
          cellsCrc({&s.keys(), &s.log_odds(), s.has_map_kind() ? &s.map_kind() : &no_kind})) {
    return fileError(file, "snapshot cells fail their CRC-32 (corrupt)");
  }
  if (expected_resolution_m > 0 && s.resolution_m() != expected_resolution_m) {
    return fileError(file, "snapshot resolution " + std::to_string(s.resolution_m()) +
                               " m differs from the configured " +
                               std::to_string(expected_resolution_m) + " m");
  }
  const SensorProbabilities p{s.sensor().prob_hit(), s.sensor().prob_miss(), s.sensor().clamp_min(),
                              s.sensor().clamp_max()};
  const SensorModel model(p);
  if (!model.isValid() ||
      !(p.hit < 1.0 && p.clamp_max < 1.0 && p.miss > 0.0 && p.clamp_min > 0.0)) {
    return fileError(file,
                     "snapshot sensor model is invalid (probabilities outside (0, 1) or "
                     "hit, miss and clamping on the wrong sides of 0.5)");
  }
  // A log-odds map's values never leave the clamp range (every update clamps); a dense map's
  // logit(p) may.
  const bool clamped = !s.has_kernel_method() && (!s.has_map_kind() || s.map_kind() == "log_odds");
  if (s.has_map_kind() && s.map_kind() != "unclamped" && !kernel::parseMapKind(s.map_kind())) {
    return fileError(file, "unknown map kind '" + s.map_kind() + "'");
  }
  auto map = makeMap(backend, s.resolution_m(), model);
  if (!map) return fileError(file, map.error().message);
  for (std::size_t i = 0; i < n; ++i) {
    std::uint16_t xyz[3];
    float v;
    std::memcpy(xyz, s.keys().data() + i * 6, 6);
    std::memcpy(&v, s.log_odds().data() + i * 4, 4);
    // Values from outside: a CRC proves the file whole, not its values sane.
    if (!std::isfinite(v)) {
      return fileError(file, "snapshot cell " + std::to_string(i) + " (key " +
                                 std::to_string(xyz[0]) + " " + std::to_string(xyz[1]) + " " +
                                 std::to_string(xyz[2]) + ") has a non-finite log-odds");
    }
    if (clamped && (v < model.clampMin() || v > model.clampMax())) {
      return fileError(file, "snapshot cell " + std::to_string(i) + " (key " +
                                 std::to_string(xyz[0]) + " " + std::to_string(xyz[1]) + " " +
                                 std::to_string(xyz[2]) + ") has log-odds " + std::to_string(v) +
                                 ", outside the sensor model's clamp range [" +
                                 std::to_string(model.clampMin()) + ", " +
                                 std::to_string(model.clampMax()) + "]");
    }
    (*map)->setLogOdds(VoxelKey{xyz[0], xyz[1], xyz[2]}, v);
  }
  auto evidence = kernelEvidenceOf(s);
  if (!evidence) return fileError(file, evidence.error().message);
  return LoadedSnapshot{std::move(*map), s.map_version(), std::move(*evidence)};
}

std::filesystem::path snapshotGeneration(const std::filesystem::path& path, int g) {
  if (g == 0) return path;
  return std::filesystem::path(path.string() + (g < 0 ? ".new" : "." + std::to_string(g)));
}

Expected<std::size_t> saveSnapshotKeeping(const MapView& view, const SensorModel& model,
                                          Backend backend, const std::filesystem::path& path,
                                          int keep, const kernel::KernelEvidence* kernel) {
  if (keep < 1 || keep > 100) return makeError("snapshot.keep must be 1 .. 100");
  // The extension decides the format: write `path.new` as `path` would be written.
  const std::string ext = path.extension().string();
  if (ext == ".bt" || ext == ".ot") {
    return saveSnapshot(view, model, backend, path, kernel);  // OctoMap files: no generations
  }
  const std::filesystem::path fresh = snapshotGeneration(path, -1);
  auto size = saveSnapshot(view, model, backend, fresh, kernel);
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
