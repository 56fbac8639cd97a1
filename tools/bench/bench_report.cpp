#include "bench_report.hpp"

#include "densemap/geometry/percentile.hpp"

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <sstream>

namespace densemap::bench {

double RunResult::percentile(double q) const { return densemap::percentile(ms_per_scan, q); }

double RunResult::withinTurnP50() const { return densemap::percentile(ms_within_turn, 0.5); }

double RunResult::openingTurnP50() const { return densemap::percentile(ms_opening_turn, 0.5); }

std::string formatFieldTable(const std::vector<RunResult>& runs) {
  std::string out;
  char line[200];
  for (const RunResult& r : runs) {
    if (r.esdf_ms.empty()) continue;
    if (out.empty()) {
      std::snprintf(line, sizeof(line), "%-16s %-7s %3s %10s %10s %10s %8s %10s %9s %9s\n",
                    "distance field", "backend", "thr", "p50 ms", "p99 ms", "integ p50", "ratio",
                    "chg/scan", "field MiB", "map MiB");
      out += line;
    }
    const double p50 = densemap::percentile(r.esdf_ms, 0.5);
    const double integration = r.percentile(0.5);
    std::snprintf(
        line, sizeof(line), "%-16s %-7s %3d %10.2f %10.2f %10.2f %8.2f %10.0f %9.1f %9.1f\n",
        r.method.c_str(), r.backend.c_str(), r.threads, p50, densemap::percentile(r.esdf_ms, 0.99),
        integration, integration > 0 ? p50 / integration : 0.0, r.esdf_changes_per_scan,
        static_cast<double>(r.field_bytes) / 1048576.0,
        static_cast<double>(r.memory_bytes) / 1048576.0);
    out += line;
  }
  return out;
}

std::string formatTurnTable(const std::vector<RunResult>& runs) {
  bool turns = false;
  for (const RunResult& r : runs) turns = turns || r.ms_opening_turn.size() > 1;
  if (!turns) return {};
  std::string out =
      "p50 of the scans that open a lane's turn (the other lanes ran before them) and of the "
      "rest\n";
  char line[160];
  std::snprintf(line, sizeof(line), "%-16s %-7s %3s %8s %10s %8s %10s\n", "method", "backend",
                "thr", "openers", "p50 ms", "rest", "p50 ms");
  out += line;
  for (const RunResult& r : runs) {
    std::snprintf(line, sizeof(line), "%-16s %-7s %3d %8zu %10.1f %8zu %10.1f\n", r.method.c_str(),
                  r.backend.c_str(), r.threads, r.ms_opening_turn.size(), r.openingTurnP50(),
                  r.ms_within_turn.size(), r.withinTurnP50());
    out += line;
  }
  return out;
}

std::string formatTable(const std::vector<RunResult>& runs) {
  std::ostringstream out;
  char line[512];
  std::snprintf(line, sizeof(line),
                "%-16s %-7s %-7s %3s %6s %10s %9s %9s %11s %11s %11s %10s %8s\n", "method",
                "backend", "rule", "thr", "scans", "points", "p50 ms", "p99 ms", "points/s",
                "visits/scan", "chg/scan", "diff cells", "speedup");
  out << line;
  for (const RunResult& r : runs) {
    const std::string visits = r.has_counts ? std::to_string(std::llround(r.visits_per_scan)) : "-";
    const std::string changed =
        r.has_counts ? std::to_string(std::llround(r.changed_cells_per_scan)) : "-";
    const std::string diff = r.diff_cells < 0 ? "-" : std::to_string(r.diff_cells);
    char speed[32] = "-";
    if (r.speedup_vs_octomap > 0)
      std::snprintf(speed, sizeof(speed), "%.2fx", r.speedup_vs_octomap);
    std::snprintf(line, sizeof(line),
                  "%-16s %-7s %-7s %3d %6zu %10zu %9.1f %9.1f %11.3g %11s %11s %10s %8s\n",
                  r.method.c_str(), r.backend.c_str(), r.rule.c_str(), r.threads, r.scans, r.points,
                  r.percentile(0.5), r.percentile(0.99), r.pointsPerSecond(), visits.c_str(),
                  changed.c_str(), diff.c_str(), speed);
    out << line;
  }
  return out.str();
}

std::string formatRayTable(const std::vector<RunResult>& runs) {
  std::ostringstream out;
  char line[512];
  std::snprintf(line, sizeof(line), "%-16s %-7s %11s %11s %8s %11s %11s %7s %8s %12s %12s   %s\n",
                "method", "backend", "rays/scan", "super/scan", "pts/ray", "visits/scan",
                "cells/scan", "v/cell", "ns/visit", "culled/scan", "region/scan",
                "mean ms: rays region mark merge apply");
  out << line;
  for (const RunResult& r : runs) {
    if (!r.has_counts) continue;
    const double points_per_scan = r.scans > 0 ? static_cast<double>(r.points) / r.scans : 0;
    std::snprintf(
        line, sizeof(line),
        "%-16s %-7s %11.0f %11.0f %8.2f %11.0f %11.0f %7.2f %8.2f %12.0f %12.0f   %.1f %.1f %.1f "
        "%.1f %.1f%s\n",
        r.method.c_str(), r.backend.c_str(), r.rays_per_scan, r.super_rays_per_scan,
        r.rays_per_scan > 0 ? points_per_scan / r.rays_per_scan : 0.0, r.visits_per_scan,
        r.cells_per_scan, r.cells_per_scan > 0 ? r.visits_per_scan / r.cells_per_scan : 0.0,
        r.nsPerVisit(), r.culled_per_scan, r.region_voxels_per_scan, r.ms_stage[0], r.ms_stage[1],
        r.ms_stage[2], r.ms_stage[3], r.ms_stage[4],
        r.dense ? "  (dense: samples kernels occupied free apply)" : "");
    out << line;
  }
  return out.str();
}

namespace {

std::string quoted(const std::string& s) {
  std::string q = "\"";
  for (const char c : s) {
    if (c == '"' || c == '\\') q += '\\';
    q += c;
  }
  return q + "\"";
}

std::string number(double v) {
  if (!std::isfinite(v)) return "null";
  char buf[64];
  std::snprintf(buf, sizeof(buf), "%.6g", v);
  return buf;
}

}  // namespace

std::string formatJson(const std::vector<RunResult>& runs, const std::string& data,
                       const std::string& machine, const CacheProbes& probes) {
  std::ostringstream out;
  out << "{\n  \"data\": " << quoted(data) << ",\n  \"machine\": " << quoted(machine);
  if (!probes.before.empty()) {
    // ns a step per vCPU; null where a vCPU could not be probed.
    const auto list = [](const std::vector<double>& ns) {
      std::string s = "[";
      for (std::size_t k = 0; k < ns.size(); ++k) {
        s += (k ? ", " : "") + (ns[k] < 0 ? std::string("null") : number(ns[k]));
      }
      return s + "]";
    };
    out << ",\n  \"cache_probe\": {\"bytes\": " << probes.bytes
        << ", \"ns_per_step_before\": " << list(probes.before)
        << ", \"ns_per_step_after\": " << list(probes.after) << "}";
  }
  out << ",\n  \"runs\": [\n";
  for (std::size_t i = 0; i < runs.size(); ++i) {
    const RunResult& r = runs[i];
    out << "    {\"method\": " << quoted(r.method) << ", \"backend\": " << quoted(r.backend)
        << ", \"rule\": " << quoted(r.rule) << ", \"threads\": " << r.threads
        << ", \"resolution\": " << number(r.resolution)
        << ", \"max_range\": " << number(r.max_range) << ", \"scans\": " << r.scans
        << ", \"points\": " << r.points << ", \"ms_per_scan_p50\": " << number(r.percentile(0.5))
        << ", \"ms_per_scan_p99\": " << number(r.percentile(0.99))
        << ", \"ms_opening_turn_p50\": " << number(r.openingTurnP50())
        << ", \"ms_within_turn_p50\": " << number(r.withinTurnP50())
        << ", \"points_per_s\": " << number(r.pointsPerSecond())
        << ", \"visits_per_scan\": " << (r.has_counts ? number(r.visits_per_scan) : "null")
        << ", \"changed_cells_per_scan\": "
        << (r.has_counts ? number(r.changed_cells_per_scan) : "null")
        << ", \"cells_per_scan\": " << (r.has_counts ? number(r.cells_per_scan) : "null")
        << ", \"ns_per_visit\": " << (r.has_counts ? number(r.nsPerVisit()) : "null")
        << ", \"rays_per_scan\": " << (r.has_counts ? number(r.rays_per_scan) : "null")
        << ", \"super_rays_per_scan\": " << (r.has_counts ? number(r.super_rays_per_scan) : "null")
        << ", \"culled_steps_per_scan\": " << (r.has_counts ? number(r.culled_per_scan) : "null")
        << ", \"region_voxels_per_scan\": "
        << (r.has_counts ? number(r.region_voxels_per_scan) : "null")
        << ", \"reference\": " << quoted(r.reference) << ", \"diff_cells_vs_reference\": "
        << (r.diff_cells < 0 ? "null" : std::to_string(r.diff_cells))
        << ", \"diff_cells_vs_octomap\": "
        << (r.diff_cells_vs_octomap < 0 ? "null" : std::to_string(r.diff_cells_vs_octomap))
        << ", \"speedup_vs_octomap\": "
        << (r.speedup_vs_octomap > 0 ? number(r.speedup_vs_octomap) : "null")
        << ", \"cpu_steal_share\": "
        << (r.cpu_steal_share >= 0 ? number(r.cpu_steal_share) : "null")
        << ", \"total_s\": " << number(r.total_s) << ", \"known_cells\": " << r.known_cells
        << ", \"memory_bytes\": " << r.memory_bytes << "}" << (i + 1 < runs.size() ? "," : "")
        << "\n";
  }
  out << "  ]\n}\n";
  return out.str();
}

}  // namespace densemap::bench
