#include "densemap/sim/lidar_model.hpp"

#include <cmath>

namespace densemap {
namespace {

std::vector<double> linspace(double first, double last, int n) {
  std::vector<double> v(n);
  for (int i = 0; i < n; ++i) v[i] = first + (last - first) * i / (n - 1);
  return v;
}

}  // namespace

Expected<void> LidarModel::validate() const {
  if (elevations_deg.empty()) return makeError("lidar '" + name + "' has no beams");
  for (const double e : elevations_deg) {
    if (!std::isfinite(e) || std::abs(e) > 90) return makeError("beam elevation out of [-90, 90]");
  }
  if (columns <= 0 || columns > 65536) return makeError("columns must be in 1..65536");
  if (!(min_range_m >= 0 && max_range_m > min_range_m && max_range_m < 10000)) {
    return makeError("need 0 <= min range < max range < 10 km");
  }
  if (!(noise_std_m >= 0 && noise_std_m < 10)) return makeError("noise std must be in [0, 10) m");
  if (!(dropout >= 0 && dropout < 1)) return makeError("dropout must be in [0, 1)");
  return {};
}

Expected<LidarModel> lidarPreset(const std::string& name) {
  LidarModel m;
  m.name = name;
  if (name == "vlp16") {
    m.elevations_deg = linspace(15, -15, 16);
    m.columns = 1800;
    m.max_range_m = 100;
  } else if (name == "hdl64") {
    m.elevations_deg = linspace(2.0, -8.33, 32);
    const auto lower = linspace(-8.83, -24.33, 32);
    m.elevations_deg.insert(m.elevations_deg.end(), lower.begin(), lower.end());
    m.columns = 1800;
    m.max_range_m = 120;
  } else if (name == "os128") {
    m.elevations_deg = linspace(22.5, -22.5, 128);
    m.columns = 1024;
    m.max_range_m = 120;
  } else if (name == "os0-64") {
    m.elevations_deg = linspace(45, -45, 64);
    m.columns = 1024;
    m.max_range_m = 50;
  } else {
    return makeError("unknown sensor '" + name + "' (vlp16, hdl64, os128, os0-64)");
  }
  return m;
}

}  // namespace densemap
