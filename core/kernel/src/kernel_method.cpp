#include "densemap/kernel/kernel_evidence.hpp"

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

Expected<std::optional<KernelMethod>> parseMapKind(std::string_view name) {
  if (name == "log_odds") return std::optional<KernelMethod>();
  auto kernel = parseKernelMethod(name);
  if (!kernel) {
    return makeError("unknown kind '" + std::string(name) +
                     "' (expected log_odds, akimap, bgk, bgkl or akimap_rays)");
  }
  return std::optional<KernelMethod>(*kernel);
}

}  // namespace densemap::kernel
