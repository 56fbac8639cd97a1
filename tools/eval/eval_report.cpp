#include "eval_report.hpp"

#include <cmath>
#include <cstdio>
#include <fstream>
#include <sstream>
#include <utility>

#include "densemap/io/file_bytes.hpp"

namespace densemap::tools {

Expected<void> addRocCurve(const EvalOptions& o, const std::string& method,
                           const std::vector<eval::Prediction>& predictions, double auc,
                           Curves& curves) {
  const std::string path = o.roc_prefix + "_" + method + ".csv";
  std::ofstream csv(path);
  csv << "threshold,false_positive_rate,true_positive_rate\n";
  auto curve = eval::rocCurve(predictions);
  for (const auto& p : curve) {
    csv << p.threshold << ',' << p.false_positive_rate << ',' << p.true_positive_rate << '\n';
  }
  if (!csv) return makeError("cannot write " + path);
  curves.roc.push_back({method, auc, std::move(curve)});
  return {};
}

Expected<void> writeCurves(const EvalOptions& o, const Curves& curves) {
  if (!curves.roc.empty()) {
    std::ostringstream title;
    title << "ROC, " << o.protocol << " protocol, " << o.resolution << " m";
    if (auto ok = writeRocSvg(o.roc_prefix + ".svg", title.str(), curves.roc); !ok) return ok;
    std::fprintf(stderr, "densemap-eval: wrote %s.svg\n", o.roc_prefix.c_str());
  }
  if (!curves.reliability.empty()) {
    std::ostringstream title, csv;
    title << "Reliability, " << o.protocol << " protocol, " << o.resolution << " m";
    csv << "method,bin_lower,bin_upper,count,mean_predicted,observed\n";
    for (const auto& s : curves.reliability) {
      for (const auto& b : s.bins) {
        csv << s.name << ',' << b.lower << ',' << b.upper << ',' << b.count << ','
            << b.mean_predicted << ',' << b.observed << '\n';
      }
    }
    if (auto ok = writeFileAtomically(o.reliability_prefix + ".csv", csv.str()); !ok) return ok;
    if (auto ok =
            writeReliabilitySvg(o.reliability_prefix + ".svg", title.str(), curves.reliability);
        !ok) {
      return ok;
    }
    std::fprintf(stderr, "densemap-eval: wrote %s.csv and %s.svg\n", o.reliability_prefix.c_str(),
                 o.reliability_prefix.c_str());
  }
  return {};
}

namespace {

/// Mean and (population) standard deviation of one field over the runs.
template <class Field>
std::pair<double, double> meanAndSpread(const std::vector<RunResult>& rs, Field field) {
  double mean = 0.0, sq = 0.0;
  for (const RunResult& r : rs) mean += field(r);
  mean /= static_cast<double>(rs.size());
  for (const RunResult& r : rs) sq += (field(r) - mean) * (field(r) - mean);
  return {mean, std::sqrt(sq / static_cast<double>(rs.size()))};
}

}  // namespace

Expected<void> reportResults(const EvalOptions& o, const std::vector<std::string>& methods,
                             const std::vector<std::vector<RunResult>>& results,
                             std::size_t scans) {
  std::printf("densemap-eval: %s, protocol %s, resolution %g m, %zu scans, %d run(s), seed %llu\n",
              o.data.c_str(), o.protocol.c_str(), o.resolution, scans, o.runs,
              static_cast<unsigned long long>(o.seed));
  std::printf("%-11s %14s %7s %7s %7s %8s %7s %8s %7s %8s %8s\n", "method", "auc (+-sd)", "mse",
              "ece", "acc_occ", "acc_free", "occ>0.7", "free<0.3", "known", "build_s", "ms/scan");
  std::string json = "{\"results\": [";
  for (std::size_t m = 0; m < methods.size(); ++m) {
    const auto& rs = results[m];
    const auto mean = [&](auto field) { return meanAndSpread(rs, field).first; };
    const auto auc = meanAndSpread(rs, [](const RunResult& r) { return r.metrics.auc; });
    const double mse = mean([](const RunResult& r) { return r.metrics.mse; });
    const double occ = mean([](const RunResult& r) { return r.metrics.acc_occupied; });
    const double fre = mean([](const RunResult& r) { return r.metrics.acc_free; });
    const double occ_band = mean([](const RunResult& r) { return r.metrics.acc_occupied_band; });
    const double free_band = mean([](const RunResult& r) { return r.metrics.acc_free_band; });
    const double build = mean([](const RunResult& r) { return r.build_s; });
    const double ms = mean([](const RunResult& r) { return r.ms_per_scan; });
    const double ece = mean([](const RunResult& r) { return r.metrics.ece; });
    const double known = mean([](const RunResult& r) { return r.metrics.coverage; });
    std::printf("%-11s %7.4f+-%.4f %7.4f %7.4f %7.4f %8.4f %7.4f %8.4f %7.4f %8.2f %8.1f\n",
                methods[m].c_str(), auc.first, auc.second, mse, ece, occ, fre, occ_band, free_band,
                known, build, ms);
    char entry[768];
    std::snprintf(entry, sizeof(entry),
                  "%s{\"method\": \"%s\", \"protocol\": \"%s\", \"resolution\": %g, \"auc\": %.6f, "
                  "\"auc_sd\": %.6f, \"mse\": %.6f, \"acc_occupied\": %.6f, \"acc_free\": %.6f, "
                  "\"build_s\": %.4f, \"ms_per_scan\": %.3f, \"ece\": %.6f, \"known\": %.6f, "
                  "\"runs\": %d}",
                  m == 0 ? "" : ", ", methods[m].c_str(), o.protocol.c_str(), o.resolution,
                  auc.first, auc.second, mse, occ, fre, build, ms, ece, known, o.runs);
    json += entry;
  }
  json += "]}\n";
  if (!o.json_path.empty()) return writeFileAtomically(o.json_path, json);
  return {};
}

}  // namespace densemap::tools
