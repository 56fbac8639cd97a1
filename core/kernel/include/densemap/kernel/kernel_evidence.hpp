#pragma once

// The dense map kinds by name and a kernel map's evidence as plain data: what snapshots read
// and write, without the kernel engine (and its TBB) behind them.
#include <cstdint>
#include <optional>
#include <string_view>
#include <vector>

#include "densemap/geometry/error.hpp"
#include "densemap/geometry/voxel_key.hpp"

namespace densemap::kernel {

/// One engine, four configurations (dissertation Ch. 3, its baselines, and their combination).
enum class KernelMethod {
  kAkimap,  // adaptive anisotropic kernels, random free samples
  kBgk,     // BGKOctoMap: isotropic kernels on points, regular free points
  kBgkl,    // BGKOctoMap-L: isotropic kernels on points, free ray segments
  /// AKIMap's adaptive kernels for occupied evidence (their scale fitted to the neighbouring
  /// hits; with negative_step > 0 also against AKIMap's random free samples, which add no
  /// evidence themselves) and free evidence from segment
  /// kernels that cover every ray up to `free_margin` short of its hit: the rays' free space
  /// is covered as by BGKOctoMap-L, without blurring free evidence into the surfaces.
  kAkimapRays,
};

[[nodiscard]] std::string_view kernelMethodName(KernelMethod method);
[[nodiscard]] Expected<KernelMethod> parseKernelMethod(std::string_view name);
/// A map kind by name: "log_odds" (none: OctoMap's log-odds map) or a kernel method; the error
/// lists every kind.
[[nodiscard]] Expected<std::optional<KernelMethod>> parseMapKind(std::string_view name);

/// A kernel map's evidence, for snapshots: per known cell its alpha and beta (the
/// prior not included), in block order, and the scans integrated (the random free samples'
/// counter, so that a restored map's next scan draws what the original's would).
struct KernelEvidence {
  KernelMethod method = KernelMethod::kAkimapRays;
  double resolution_m = 0.0;
  std::uint64_t scans = 0;
  std::vector<VoxelKey> keys;
  std::vector<double> alpha, beta;
};

}  // namespace densemap::kernel
