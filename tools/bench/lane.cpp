#include "lane.hpp"

#include <charconv>
#include <cstring>

#include "densemap/map/octree_map.hpp"
#include "densemap/traversal/update_rule.hpp"

namespace densemap::bench {

std::uint64_t evidenceDigest(const kernel::KernelEvidence& e) {
  std::uint64_t h = 0xcbf29ce484222325ULL;
  const auto mix = [&h](const void* data, std::size_t bytes) {
    const auto* p = static_cast<const unsigned char*>(data);
    for (std::size_t i = 0; i < bytes; ++i) h = (h ^ p[i]) * 0x100000001b3ULL;
  };
  for (std::size_t i = 0; i < e.keys.size(); ++i) {
    const std::uint64_t key = e.keys[i].packed();
    mix(&key, sizeof key);
    mix(&e.alpha[i], sizeof(double));
    mix(&e.beta[i], sizeof(double));
  }
  return h;
}

Expected<kernel::KernelOptions> kernelOptions(const std::string& method, const Options& o) {
  const auto at = method.find('@');
  const std::string kind = method.substr(0, at);
  auto parsed = kernel::parseKernelMethod(kind);
  if (!parsed) return std::unexpected(parsed.error());
  kernel::KernelOptions k = kernel::KernelOptions::defaults(*parsed);
  k.max_range = o.max_range;
  if (auto ok = kernel::applySettings(k, o.kernel_settings); !ok)
    return std::unexpected(ok.error());
  if (at != std::string::npos) {  // after --kernel-set: the variant is what the name says
    const std::string variant = method.substr(at + 1);
    if (variant == "plain") {
      k.free_traversal = false;
      k.aggregate_hits = false;
    } else if (variant.starts_with("set=")) {
      // `kind@set=NAME=VALUE:NAME=VALUE`: settings for this lane only (a setting against the
      // default in one run; methods are comma-separated, so settings are colon-separated).
      std::vector<std::string> settings;
      for (std::size_t from = 4; from <= variant.size();) {
        const std::size_t colon = std::min(variant.find(':', from), variant.size());
        settings.push_back(variant.substr(from, colon - from));
        from = colon + 1;
      }
      if (auto ok = kernel::applySettings(k, settings); !ok) {
        return makeError("'" + method + "': " + ok.error().message);
      }
    } else {
      return makeError("unknown variant in '" + method + "'");
    }
  }
  return k;
}

LaneMethod laneMethod(const std::string& name, int threads) {
  const std::size_t at = name.rfind("@t");
  if (at == std::string::npos || at + 2 == name.size()) return {name, threads};
  int n = 0;
  const char* end = name.data() + name.size();
  const auto [ptr, ec] = std::from_chars(name.data() + at + 2, end, n);
  if (ec != std::errc() || ptr != end || n < 1 || n > 256) return {name, threads};
  return {name.substr(0, at), n};
}

Integrate makeIntegrator(const std::string& method, const Options& o) {
  if (method == "octomap") {
    return [range = o.max_range](OccupancyMap& map, const WorldScan& s) {
      static_cast<OctreeMap&>(map).insertWithOctomap(s.points, s.origin, range);
      return ScanStats{s.points.size(), 0, 0, 0};
    };
  }
  // `method@nogrow`: the culling region from the map only (no growth by the scan's marks);
  // `method@grow=A:B:..`: these strides instead of --grow-strides; `method@single`: walks one
  // at a time as they come (IntegratorOptions::queue_walks off); `method@four` / `@fixed` /
  // `@sixteen` / `@scalar`: the queued walks four at a time in AVX2 lanes of doubles / eight in
  // AVX2 lanes of fixed point / sixteen in AVX-512 lanes of fixed point / one at a time
  // (WalkKernel kFour / kFixedEight / kFixedSixteen / kScalar; the default, kBest, is
  // kFixedSixteen's with AVX-512, else kFixedEight's).
  const std::size_t at = method.find('@');
  std::vector<std::size_t> strides = o.grow_strides;
  bool queue_walks = true;
  DenseMarks::WalkKernel kernel = DenseMarks::WalkKernel::kBest;
  if (at != std::string::npos) {
    const std::string variant = method.substr(at + 1);
    if (variant == "single") {
      queue_walks = false;
    } else if (variant == "four") {
      kernel = DenseMarks::WalkKernel::kFour;
    } else if (variant == "fixed") {
      kernel = DenseMarks::WalkKernel::kFixedEight;
    } else if (variant == "sixteen") {
      kernel = DenseMarks::WalkKernel::kFixedSixteen;
    } else if (variant == "scalar") {
      kernel = DenseMarks::WalkKernel::kScalar;
    } else if (variant == "nogrow") {
      strides.clear();
    } else if (variant.starts_with("grow=")) {
      strides.clear();
      for (std::size_t p = 5; p < variant.size();) {
        std::size_t end = variant.find(':', p);
        if (end == std::string::npos) end = variant.size();
        std::size_t value = 0;
        const auto [ptr, ec] = std::from_chars(variant.data() + p, variant.data() + end, value);
        if (ec != std::errc() || ptr != variant.data() + end) return nullptr;
        strides.push_back(value);
        p = end + 1;
      }
    } else {
      return nullptr;
    }
  }
  const auto parsed = parseIntegrationMethod(method.substr(0, at));
  const auto rule = parseUpdateRule(o.rule);
  if (!parsed || !rule) return nullptr;
  IntegratorOptions options{.method = *parsed,
                            .rule = *rule,
                            .max_range_m = o.max_range,
                            .superray_min_points = o.min_points};
  options.grow_strides = strides;
  options.queue_walks = queue_walks;
  options.walk_kernel = kernel;
  auto integrator = std::make_shared<Integrator>(options);
  return [integrator](OccupancyMap& map, const WorldScan& s) {
    return integrator->integrate(map, s.points, s.origin);
  };
}

}  // namespace densemap::bench
