#include "densemap/sim/trajectory.hpp"

#include <cmath>

namespace densemap {

std::vector<Transform> trajectoryAlong(const std::vector<Eigen::Vector3d>& waypoints, int n) {
  std::vector<Transform> poses;
  if (waypoints.empty() || n <= 0) return poses;
  std::vector<double> cumulative{0.0};
  for (std::size_t i = 1; i < waypoints.size(); ++i) {
    cumulative.push_back(cumulative.back() + (waypoints[i] - waypoints[i - 1]).norm());
  }
  const double total = cumulative.back();
  for (int k = 0; k < n; ++k) {
    Transform T = Transform::Identity();
    if (total <= 0.0) {
      T.translation() = waypoints.front();
      T.linear() = Eigen::AngleAxisd(2 * M_PI * k / n, Eigen::Vector3d::UnitZ()).toRotationMatrix();
      poses.push_back(T);
      continue;
    }
    const double s = n == 1 ? 0.0 : total * k / (n - 1);
    std::size_t seg = 1;
    while (seg + 1 < waypoints.size() && cumulative[seg] < s) ++seg;
    const double len = cumulative[seg] - cumulative[seg - 1];
    const double a = len > 0 ? (s - cumulative[seg - 1]) / len : 0.0;
    const Eigen::Vector3d dir = waypoints[seg] - waypoints[seg - 1];
    T.translation() = waypoints[seg - 1] + a * dir;
    T.linear() = Eigen::AngleAxisd(std::atan2(dir.y(), dir.x()), Eigen::Vector3d::UnitZ())
                     .toRotationMatrix();
    poses.push_back(T);
  }
  return poses;
}

std::vector<Transform> posesAtStations(const std::vector<Eigen::Vector3d>& stations, int n) {
  std::vector<Transform> poses;
  if (stations.empty() || n <= 0) return poses;
  const int count = static_cast<int>(stations.size());
  for (int s = 0; s < count; ++s) {
    const int here = n / count + (s < n % count ? 1 : 0);
    for (int k = 0; k < here; ++k) {
      Transform T = Transform::Identity();
      T.translation() = stations[static_cast<std::size_t>(s)];
      // An irrational step: yaws never repeat the azimuth grid of an earlier scan.
      T.linear() =
          Eigen::AngleAxisd(k * 2.0 * M_PI / (here * 1.4142135623730951), Eigen::Vector3d::UnitZ())
              .toRotationMatrix();
      poses.push_back(T);
    }
  }
  return poses;
}

}  // namespace densemap
