#include "densemap/kernel/kernel_map.hpp"

#include <map>
#include <string>

namespace densemap::kernel {

KernelOptions KernelOptions::defaults(KernelMethod method) {
  KernelOptions o;
  o.method = method;
  if (method == KernelMethod::kBgkl) {
    o.free_step = 0.3;
    o.sf2 = 0.1;
  }
  if (method == KernelMethod::kAkimapRays) {
    // Settings chosen on the oracle scenes at 0.1 and 0.05 m, the la3dm and AKIMap hold-outs and
    // BALM's hold-out, 3 seeds each (scripts/dense-map-benchmark.sh; docs/dense-maps.md).
    // Occupied kernels of weight 0.7 plus each hit's cell (0.9) and a 2-voxel kernel around it
    // (0.3); free segments of 0.3 m, radius 0.15 m, weight 0.4, stopping 0.2 m from the surface,
    // then a 0.1 m thin tip to 0.05 m from it. A larger hit_weight lowers the AKIMap sample's
    // MSE further but costs la3dm's AUC (docs/benchmarks.md).
    o.free_step = 0.3;
    o.length_scale = 0.15;
    o.sf2 = 0.4;
    o.occupied_weight = 0.7;
    o.hit_weight = 0.9;
    o.hit_kernel_weight = 0.3;
    o.hit_length_voxels = 2.0;
    // Hit kernels from tables, centred on the nearest of 5^3 points across the voxel, faces
    // included: points inside the voxel only would move a surface lying on a voxel face by
    // 1/8 voxel, and a grazing floor would lose its cells.
    o.hit_stencil_steps = 4.0;
    // Pulling the centres toward the voxel's centre helps the oracle scenes but costs la3dm's
    // AUC and a grazing floor's cells, for the same reason as above.
    o.free_margin = 0.2;
    o.max_margin = 1.0;
    o.tip_margin = 0.05;
    o.tip_length_scale = 0.1;
    // The same model at speed: each ray's free extent as one capsule (its joints' extra
    // evidence carried as a mean), one adaptive kernel per voxel of several hits.
    o.free_traversal = true;
    o.aggregate_hits = true;
    // The capsules' outer 15% of radius hold 0.02% of the evidence in 28% of the voxels; a
    // smaller reach leaves cells of sparse scans unknown.
    o.free_reach = 0.85;
    o.free_bundles = true;
    // Bundle rays by 0.2 m cubes where voxels are finer (at 0.1 m most voxels hold one hit, so
    // voxel bundles would not bundle); larger cubes cost BALM's hold-out MSE.
    o.free_bundle_m = 0.2;
    // The cubes' bundles bundled again up a tree of cubes twice as large a level, each level
    // over the part of its rays where they run as close as a cube's rays do at its end: the
    // same accuracy on every row with fewer capsule visits (docs/benchmarks.md). Six levels
    // reach 12.8 m cubes at 0.2 m, within a few metres of the origin.
    o.free_bundle_levels = 6.0;
    // From 3 hits a voxel gets one kernel at their mean; at 2 a grazing floor loses its cells
    // (the AkimapRays test), so 2 hits keep a kernel each, of one shape fitted once.
    o.aggregate_min_hits = 3.0;
    o.shared_fit_min_hits = 2.0;
    // The voxels of hits in a 0.4 m cube share the fit of its fullest voxel (2 voxels a side
    // at 0.2 m, 4 at 0.1 m): every accuracy row within 0.001 AUC and 3% MSE, the kernels
    // stage a third shorter on BALM at 0.1 m (docs/benchmarks.md).
    o.fit_cube_m = 0.4;
    // AKIMap's random free samples only shape the occupied kernels' scale and change no
    // accuracy row measurably; without them the fits cover the hits only.
    // negative_step=0.5 gives AKIMap's samples back.
    o.negative_step = 0.0;
  }
  return o;
}

Expected<void> applySettings(KernelOptions& options, const std::vector<std::string>& settings) {
  const std::pair<std::string_view, double KernelOptions::*> fields[] = {
      {"free_step", &KernelOptions::free_step},
      {"length_scale", &KernelOptions::length_scale},
      {"sf2", &KernelOptions::sf2},
      {"prior", &KernelOptions::prior},
      {"free_margin", &KernelOptions::free_margin},
      {"max_margin", &KernelOptions::max_margin},
      {"tip_margin", &KernelOptions::tip_margin},
      {"tip_length_scale", &KernelOptions::tip_length_scale},
      {"occupied_weight", &KernelOptions::occupied_weight},
      {"hit_weight", &KernelOptions::hit_weight},
      {"hit_length_voxels", &KernelOptions::hit_length_voxels},
      {"hit_kernel_weight", &KernelOptions::hit_kernel_weight},
      {"hit_stencil_steps", &KernelOptions::hit_stencil_steps},
      {"hit_centre_pull", &KernelOptions::hit_centre_pull},
      {"negative_step", &KernelOptions::negative_step},
      {"search_max", &KernelOptions::search_max},
      {"search_range", &KernelOptions::search_range},
      {"min_thickness", &KernelOptions::min_thickness},
      {"aggregate_min_hits", &KernelOptions::aggregate_min_hits},
      {"shared_fit_min_hits", &KernelOptions::shared_fit_min_hits},
      {"fit_cube_m", &KernelOptions::fit_cube_m},
      {"free_reach", &KernelOptions::free_reach},
      {"free_bundle_m", &KernelOptions::free_bundle_m},
      {"free_bundle_levels", &KernelOptions::free_bundle_levels}};
  for (const std::string& setting : settings) {
    const auto eq = setting.find('=');
    const std::string name = setting.substr(0, eq);
    if (name == "free_traversal" || name == "aggregate_hits" || name == "free_bundles") {
      const std::string value = eq == std::string::npos ? "" : setting.substr(eq + 1);
      if (value != "0" && value != "1") return makeError("'" + setting + "': expected 0 or 1");
      (name == "free_traversal"   ? options.free_traversal
       : name == "aggregate_hits" ? options.aggregate_hits
                                  : options.free_bundles) = value == "1";
      continue;
    }
    const auto field = std::find_if(std::begin(fields), std::end(fields),
                                    [&](const auto& f) { return f.first == name; });
    if (eq == std::string::npos || field == std::end(fields)) {
      return makeError("'" + setting + "' is not NAME=VALUE with a known kernel setting");
    }
    double value = 0.0;
    try {
      std::size_t used = 0;
      value = std::stod(setting.substr(eq + 1), &used);
      if (used != setting.size() - eq - 1) throw std::invalid_argument("trailing");
    } catch (const std::exception&) {
      return makeError("'" + setting + "': the value is not a number");
    }
    // Steps, scales and the prior must be positive; margins and hit weights may be 0.
    if (!std::isfinite(value) || value < 0.0 ||
        (value == 0.0 && name != "free_margin" && name != "tip_margin" && name != "hit_weight" &&
         name != "hit_kernel_weight" && name != "free_bundle_m" && name != "free_bundle_levels" &&
         name != "hit_stencil_steps" && name != "shared_fit_min_hits" && name != "fit_cube_m" &&
         name != "hit_centre_pull") ||
        value > (name == "free_reach" || name == "hit_centre_pull" ? 1.0 : 1000.0) ||
        (name == "hit_stencil_steps" && (value > 4.0 || value != std::floor(value))) ||
        (name == "free_bundle_levels" && (value > 12.0 || value != std::floor(value)))) {
      return makeError("'" + setting + "': out of range");
    }
    options.*(field->second) = value;
  }
  return {};
}

}  // namespace densemap::kernel
