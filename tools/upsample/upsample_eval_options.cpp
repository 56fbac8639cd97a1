#include "upsample_eval.hpp"

namespace densemap::tools {

void addUpsampleEvalOptions(CLI::App& app, UpsampleEvalOptions& o) {
  app.add_option("--scenes", o.scenes_list, "densemap-sim scenes (test split)")
      ->capture_default_str();
  app.add_option("--seeds", o.seeds_list, "Scene seeds (test split), e.g. 101,102 or 1..40")
      ->capture_default_str();
  app.add_option("--scans", o.scans, "Poses per scene and seed")
      ->capture_default_str()
      ->check(CLI::Range(1, 1000));
  app.add_option("--input", o.input_text, "Input grid ROWSxCOLS")->capture_default_str();
  app.add_option("--targets", o.targets_list, "Target grids, comma-separated")
      ->capture_default_str();
  app.add_option("--fov-top", o.top, "Top beam elevation, deg")->capture_default_str();
  app.add_option("--fov-bottom", o.bottom, "Bottom beam elevation, deg")->capture_default_str();
  app.add_option("--max-range", o.max_range, "Sensor range, m")->capture_default_str();
  app.add_option("--methods", o.methods_list, "bilinear, nearest, iln")->capture_default_str();
  app.add_option("--model", o.model_path, "ILN weights file (for --methods iln)")
      ->capture_default_str();
  app.add_option("--voxel", o.voxel, "Voxel size of the point metrics, m")->capture_default_str();
  app.add_option("--threads", o.threads, "Worker threads (0: all cores)")->capture_default_str();
  app.add_option("--json", o.json_path, "Write the results as JSON");
  app.add_option("--real", o.real_path,
                 "Also test on real scans (sensor frame, e.g. ../shared/data/balm-realworld): "
                 "keep every --reduce-th beam, upsample back, compare with all beams");
  app.add_option("--real-grid", o.real_layout_text,
                 "The real sensor's grid ROWSxCOLS (ROWS must match --real-beams)")
      ->capture_default_str();
  app.add_option("--real-top", o.real_top, "Its top beam, deg (BALM's OS0-64: 45.5)")
      ->capture_default_str();
  app.add_option("--real-bottom", o.real_bottom, "Its bottom beam, deg (BALM's: -44.75)")
      ->capture_default_str();
  app.add_option("--real-beams", o.real_beams_path,
                 "The real sensor's beam table (one elevation per line, deg, top first; e.g. "
                 "config/sensors/balm-os0-64.beams) instead of evenly spread beams");
  app.add_option(
      "--estimate-beams", o.estimate_beams_path,
      "Estimate the real sensor's beam table from the --real scans (20 or more; k-means on the "
      "elevations of returns beyond 3 m), write it to this file and use it");
  app.add_option("--reduce", o.reduce_text,
                 "Keep every n-th real beam; a comma-separated list tests each (e.g. 4,2)")
      ->capture_default_str();
  app.add_option("--real-first", o.real_first, "First real scan")->capture_default_str();
  app.add_option("--real-limit", o.real_limit, "Real scans to use (0: all)")->capture_default_str();
  app.add_option("--real-splits", o.real_splits_text,
                 "Report the real scans per split, NAME:FIRST-LAST of dataset indices, "
                 "comma-separated (e.g. train:0-39,test:40-79); default one split 'all'");
  app.add_option("--export-real", o.export_real_dir,
                 "Write every real scan's full range image (and the beam table) as training data "
                 "for tools/iln: DIR/index.csv, raw float32 row-major files");
  app.add_option("--export", o.export_dir,
                 "Also write every simulated range image (input and targets) as raw float32 "
                 "row-major files plus DIR/index.csv: training data for tools/iln");
}

}  // namespace densemap::tools
