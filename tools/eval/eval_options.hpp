#pragma once

#include <CLI/CLI.hpp>

#include <cstddef>
#include <cstdint>
#include <string>
#include <vector>

namespace densemap::tools {

/// densemap-eval's command line.
struct EvalOptions {
  std::string data, methods_list = "akimap,bgk,bgkl,raycast,akimap_rays", protocol = "holdout",
                    json_path, roc_prefix, reliability_prefix, slice_prefix, labels_path;
  double resolution = 0.1, max_range = -1.0, akimap_free_step = 0.5, slice_z = 1.0;
  std::uint64_t seed = 1;
  int runs = 1, threads = 0;
  std::size_t first = 0, limit = 0;
  std::vector<std::string> kernel_settings;
  std::string upsample_method, upsample_input = "16x1024", upsample_output = "64x1024",
                               upsample_model = "models/iln.pb";
  double fov_top = 15.0, fov_bottom = -15.0;
};

/// Declares every option of `o` on `app`.
void addEvalOptions(CLI::App& app, EvalOptions& o);

}  // namespace densemap::tools
