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

}  // namespace densemap::kernel
