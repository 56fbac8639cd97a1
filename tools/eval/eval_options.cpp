#include "eval_options.hpp"

namespace densemap::tools {

void addEvalOptions(CLI::App& app, EvalOptions& o) {
  app.add_option("--data", o.data, "Dataset (any format densemap reads)")->required();
  app.add_option("--method", o.methods_list,
                 "Comma-separated: akimap, bgk, bgkl, raycast, akimap_rays")
      ->capture_default_str();
  app.add_option("--protocol", o.protocol,
                 "holdout (any data) or oracle (densemap-sim data with --oracle-factor)")
      ->capture_default_str()
      ->check(CLI::IsMember({"holdout", "oracle"}));
  app.add_option("--resolution", o.resolution, "Voxel size, m")->capture_default_str();
  app.add_option("--max-range", o.max_range, "Ray cut-off, m (< 0: unlimited)")
      ->capture_default_str();
  app.add_option("--seed", o.seed, "Seed of the split and the random free samples")
      ->capture_default_str();
  app.add_option("--runs", o.runs, "Runs with seeds seed, seed+1, ...; mean and spread")
      ->capture_default_str()
      ->check(CLI::Range(1, 100));
  app.add_option("--first", o.first, "First scan index")->capture_default_str();
  app.add_option("--limit", o.limit, "Scans to use (0: all)")->capture_default_str();
  app.add_option("--threads", o.threads, "Worker threads (0: all cores)")->capture_default_str();
  app.add_option("--akimap-free-step", o.akimap_free_step,
                 "AKIMap's free sampling distance, m: one free sample drawn at random in each "
                 "such interval of a ray (the paper's 0.5)")
      ->check(CLI::Range(0.01, 10.0))
      ->capture_default_str();
  app.add_option("--kernel-set", o.kernel_settings,
                 "Override a kernel map setting for every kernel method of the run, NAME=VALUE "
                 "(repeatable): every setting of KernelOptions that applySettings names, such "
                 "as sf2, hit_weight, free_reach, fit_cube_m, or free_traversal=0|1 "
                 "(core/kernel/include/densemap/kernel/kernel_map.hpp)");
  app.add_option("--json", o.json_path, "Write the results as JSON");
  app.add_option("--roc", o.roc_prefix,
                 "Write the ROC curves of the first run: PREFIX_<method>.csv and PREFIX.svg");
  app.add_option("--reliability", o.reliability_prefix,
                 "Write the reliability diagrams of the first run (10 bins of predicted "
                 "probability: mean prediction, observed occupied share): PREFIX.csv and "
                 "PREFIX.svg");
  app.add_option("--slice", o.slice_prefix,
                 "Write a z-slice picture per method (PREFIX_<method>.png; PREFIX_oracle.png "
                 "for the oracle labels): white free, black occupied, gray unknown");
  app.add_option("--slice-z", o.slice_z, "Height of the slice, m")->capture_default_str();
  app.add_option("--labels", o.labels_path,
                 "Oracle labels file (default DATA/oracle_<resolution>.bt): score another "
                 "sensor's dataset on the same labels");
  app.add_option("--upsample", o.upsample_method,
                 "Densify each scan before mapping: bilinear, nearest or iln (sensor-frame data)")
      ->check(CLI::IsMember({"bilinear", "nearest", "iln"}));
  app.add_option("--upsample-model", o.upsample_model, "ILN weights file (--upsample iln)")
      ->capture_default_str();
  app.add_option("--upsample-input", o.upsample_input, "The sensor's grid ROWSxCOLS")
      ->capture_default_str();
  app.add_option("--upsample-output", o.upsample_output, "The grid mapped, ROWSxCOLS")
      ->capture_default_str();
  app.add_option("--fov-top", o.fov_top, "The sensor's top beam, deg")->capture_default_str();
  app.add_option("--fov-bottom", o.fov_bottom, "Its bottom beam, deg")->capture_default_str();
}

}  // namespace densemap::tools
