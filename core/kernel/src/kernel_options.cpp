#include "densemap/kernel/kernel_map.hpp"

#include <map>
#include <string>

namespace densemap::kernel {

std::string_view kernelMethodName(KernelMethod method) {
  switch (method) {
    case KernelMethod::kAkimap:
      return "akimap";
    case KernelMethod::kBgk:
      return "bgk";
    case KernelMethod::kBgkl:
      return "bgkl";
    case KernelMethod::kAkimapRays:
      return "akimap_rays";
  }
  return "unknown";
}

Expected<KernelMethod> parseKernelMethod(std::string_view name) {
  for (const auto m : {KernelMethod::kAkimap, KernelMethod::kBgk, KernelMethod::kBgkl,
                       KernelMethod::kAkimapRays}) {
    if (name == kernelMethodName(m)) return m;
  }
  return makeError("unknown kernel method '" + std::string(name) +
                   "' (expected akimap, bgk, bgkl or akimap_rays)");
}

KernelOptions KernelOptions::defaults(KernelMethod method) {
  KernelOptions o;
  o.method = method;
  if (method == KernelMethod::kBgkl) {
    o.free_step = 0.3;
    o.sf2 = 0.1;
  }
  if (method == KernelMethod::kAkimapRays) {
    // Chosen on the oracle scenes at 0.1 and 0.05 m and the la3dm and AKIMap hold-outs (issue
    // 17 note): occupied kernels of weight 1 plus each hit's cell (0.7) and a 2-voxel kernel
    // around it (0.3); free segments of 0.3 m, radius 0.15 m, weight 0.4, stopping 0.2 m from the
    // surface, then a 0.1 m thin tip to 0.05 m from it.
    o.free_step = 0.3;
    o.length_scale = 0.15;
    o.sf2 = 0.4;
    o.occupied_weight = 1.0;
    o.hit_weight = 0.7;
    o.hit_kernel_weight = 0.3;
    o.hit_length_voxels = 2.0;
    // Issue 29 (stop 48): the hit kernels tabled (HitStencils), their centres moved to
    // the nearest of 5^3 points across each voxel (and a hit's cell in the same table): the
    // occupied stage about 29% cheaper (BALM 0.2 m, 2 threads: occupied / kernels stage 0.42
    // -> 0.30). Accuracy (3 seeds), against the hits' own centres: every row within 0.0001 AUC;
    // MSE within +0.3% (AKIMap's sample 0.0350 -> 0.0351, oracle unstructured 0.1 m 0.0595 ->
    // 0.0597), la3dm and BALM's hold-out unchanged. 3 steps: AKIMap's sample +0.9%; 2: +1.7%,
    // la3dm +0.6%. Centres inside the voxels only ((i + 0.5) / 4) did better on the oracle
    // scenes (unstructured 0.1 m MSE 0.0552) but moved a surface lying on a voxel face by 1/8
    // voxel, and the grazing floor (AkimapRays test) lost its cells.
    o.hit_stencil_steps = 4.0;
    // Stop 49: hit_centre_pull (the hit kernels' centres moved toward their voxels' centres
    // before the tables quantise them) left at 0. At 0.25 and 0.5 (no centre on a face) the
    // oracle scenes gained (unstructured 0.1 m MSE 0.0593 -> 0.0507, AUC 0.9804 -> 0.9834-5;
    // the long-range row 0.0355 -> 0.0344-5) but la3dm structured's AUC fell 0.9763 -> 0.9759-60
    // (BGK-L: 0.9762) and the grazing floor (AkimapRays test) lost its cells, as with the
    // interior centres above; at 0.1 and 0.2 every row was within 0.0003 AUC and 0.0003 MSE of 0.
    o.free_margin = 0.2;
    o.max_margin = 1.0;
    o.tip_margin = 0.05;
    o.tip_length_scale = 0.1;
    // Issue 29: the same model at speed: each ray's free extent as one capsule (its joints'
    // extra evidence as a mean) and one adaptive kernel per voxel of 4+ hits; on la3dm's
    // hold-out and the oracle scenes (3 seeds) AUC within 0.0005 and MSE within +1.4% of a
    // kernel per ray piece and per hit (free_traversal=0, aggregate_hits=0), about 15x faster.
    o.free_traversal = true;
    o.aggregate_hits = true;
    // The capsules' outer 15% of radius hold 0.02% of the evidence in 28% of the voxels, but
    // cover voxels no other ray reaches on sparse scans: at 0.7 (1.0% of it, 51% of the voxels)
    // the oracle scenes' MSE rose 3.5-9% (cells left unknown); at 0.85 within 0.4% of the whole
    // kernel, la3dm's hold-out AUC within 0.0001 (3 seeds), with 72% of the voxel visits.
    o.free_reach = 0.85;
    o.free_bundles = true;
    // Issue 29's fifth stop: bundles by cubes of 0.2 m, not by voxels, where voxels are finer
    // (a 0.2 m map's bundles are its voxels, as before). At 0.1 m a BALM scan has about one hit
    // per voxel, so voxel bundles hardly bundled; 0.2 m cubes halve the free capsules' work
    // there (BALM 0.1 m: free stage 115 -> 63 ms, p50 210 -> 144 ms, 2 threads). Accuracy (3
    // seeds): AUC within 0.0003 on every row; MSE oracle structured +4.3% (0.1 m) and +3.3%
    // (0.05 m), unstructured +1.9% both, la3dm -1.6% / -2.3%, AKIMap's sample -1.4%, BALM's
    // hold-out at 0.1 m -0.6%; the oracle unstructured 0.1 m row's MSE (0.0595) no longer
    // beats BGKOctoMap-L's (0.0588). Cubes of 0.4 m on a 0.2 m map cost BALM's hold-out 17% MSE
    // (0.3 m: +4.2%, 0.25: +1.4%, for 23% and 11% of the free stage): not taken.
    o.free_bundle_m = 0.2;
    // A voxel of 3 hits: one kernel at their mean too (4 before): every row of the dense-map
    // benchmark within 0.0001 AUC and 0.3% MSE (3 seeds), BALM's hold-out unchanged, ~10% fewer
    // kernels on a BALM scan. At 2 the grazing floor (AkimapRays test) lost its cells under
    // 22-degree rays, and la3dm's AUC fell 0.0001-0.0002.
    o.aggregate_min_hits = 3.0;
    // Issue 29 (stop 48): a voxel of 2 hits keeps its two kernels, but of one shape
    // fitted once at their mean (a fit per hit before): 7% fewer instructions in the fits
    // (BALM 0.2 m); every row of the dense-map benchmark within 0.0001 AUC, MSE within 0.9%
    // (AKIMap's sample 0.0351 -> 0.0354; others equal or lower), BALM's hold-out unchanged.
    o.shared_fit_min_hits = 2.0;
    // No free samples (issue 29's fourth stop): AKIMap's random free samples only shaped the
    // occupied kernels' scale, and without them every row of the dense-map benchmark moved by
    // at most 0.0001 AUC and +0.5% MSE (3 seeds), BALM's hold-out not at all (0.2 and 0.1 m),
    // while a BALM scan at 0.2 m took 62 ms instead of 93 (the samples, the index and the fits
    // over about a fifth of the points). negative_step=0.5 gives the earlier map.
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
      {"free_reach", &KernelOptions::free_reach},
      {"free_bundle_m", &KernelOptions::free_bundle_m}};
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
         name != "hit_kernel_weight" && name != "free_bundle_m" && name != "hit_stencil_steps" &&
         name != "shared_fit_min_hits" && name != "hit_centre_pull") ||
        value > (name == "free_reach" || name == "hit_centre_pull" ? 1.0 : 1000.0) ||
        (name == "hit_stencil_steps" && (value > 4.0 || value != std::floor(value)))) {
      return makeError("'" + setting + "': out of range");
    }
    options.*(field->second) = value;
  }
  return {};
}

}  // namespace densemap::kernel
