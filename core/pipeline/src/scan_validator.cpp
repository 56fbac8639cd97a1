#include "densemap/pipeline/scan_validator.hpp"

#include <cmath>
#include <string>

namespace densemap {

std::string_view rejectReasonName(RejectReason reason) {
  switch (reason) {
    case RejectReason::kEmpty:
      return "empty";
    case RejectReason::kLengthNotMultipleOf3:
      return "length_not_multiple_of_3";
    case RejectReason::kTooManyPoints:
      return "too_many_points";
    case RejectReason::kIntensityLength:
      return "intensity_length";
    case RejectReason::kNonFinitePoint:
      return "non_finite_point";
    case RejectReason::kBadQuaternion:
      return "bad_quaternion";
    case RejectReason::kPoseOutOfBounds:
      return "pose_out_of_bounds";
    case RejectReason::kInternal:
      return "internal";
    case RejectReason::kSensorIdTooLong:
      return "sensor_id_too_long";
    case RejectReason::kCount:
      break;
  }
  return "unknown";
}

namespace {

std::unexpected<Rejection> reject(RejectReason r, std::string m) {
  return std::unexpected(Rejection{r, std::move(m)});
}

/// The rules every scan meets, in whatever frame: a point count within the limit, a sensor
/// position within limits.max_abs_position_m on every axis.
std::expected<void, Rejection> checkCount(std::size_t n, const ScanLimits& limits) {
  if (n > limits.max_points) {
    return reject(RejectReason::kTooManyPoints, std::to_string(n) + " points exceed the limit of " +
                                                    std::to_string(limits.max_points));
  }
  return {};
}

std::expected<void, Rejection> checkPosition(double t, const ScanLimits& limits) {
  if (!std::isfinite(t) || std::abs(t) > limits.max_abs_position_m) {
    return reject(RejectReason::kPoseOutOfBounds,
                  "sensor position outside +-" + std::to_string(limits.max_abs_position_m) + " m");
  }
  return {};
}

}  // namespace

std::expected<void, Rejection> checkSensorId(std::string_view sensor_id) {
  if (sensor_id.size() > kMaxSensorIdBytes) {
    return reject(RejectReason::kSensorIdTooLong,
                  "sensor id of " + std::to_string(sensor_id.size()) + " bytes exceeds " +
                      std::to_string(kMaxSensorIdBytes));
  }
  return {};
}

std::expected<void, Rejection> checkScanPose(const std::array<double, 3>& t,
                                             const std::array<double, 4>& q,
                                             const ScanLimits& limits) {
  const double q_norm = std::sqrt(q[0] * q[0] + q[1] * q[1] + q[2] * q[2] + q[3] * q[3]);
  if (!std::isfinite(q_norm) || std::abs(q_norm - 1.0) > limits.quaternion_tolerance) {
    return reject(RejectReason::kBadQuaternion,
                  "pose quaternion norm " + std::to_string(q_norm) + " is not 1");
  }
  for (const double v : t) {
    if (auto ok = checkPosition(v, limits); !ok) return ok;
  }
  return {};
}

std::expected<Scan, Rejection> validateScan(const RawScan& raw, const ScanLimits& limits) {
  if (auto ok = checkSensorId(raw.sensor_id); !ok) return std::unexpected(std::move(ok.error()));
  if (raw.xyz.empty()) return reject(RejectReason::kEmpty, "scan has no points");
  if (raw.xyz.size() % 3 != 0) {
    return reject(RejectReason::kLengthNotMultipleOf3,
                  std::to_string(raw.xyz.size()) + " coordinates is not a multiple of 3");
  }
  const std::size_t n = raw.xyz.size() / 3;
  if (auto ok = checkCount(n, limits); !ok) return std::unexpected(std::move(ok.error()));
  if (!raw.intensity.empty() && raw.intensity.size() != n) {
    return reject(
        RejectReason::kIntensityLength,
        std::to_string(raw.intensity.size()) + " intensities for " + std::to_string(n) + " points");
  }
  if (auto ok = checkScanPose(raw.t_world_sensor, raw.q_world_sensor, limits); !ok) {
    return std::unexpected(std::move(ok.error()));
  }
  const auto& q = raw.q_world_sensor;
  Scan scan;
  scan.id = raw.seq;
  scan.frame = PointFrame::kSensor;
  scan.T_world_sensor = transformFromTranslationQuaternion(
      {raw.t_world_sensor[0], raw.t_world_sensor[1], raw.t_world_sensor[2]}, q[0], q[1], q[2],
      q[3]);
  scan.points.resize(n);
  for (std::size_t i = 0; i < n; ++i) {
    const Point3f p(raw.xyz[3 * i], raw.xyz[3 * i + 1], raw.xyz[3 * i + 2]);
    if (!p.allFinite()) {
      return reject(RejectReason::kNonFinitePoint, "point " + std::to_string(i) + " is NaN or Inf");
    }
    scan.points[i] = p;
  }
  scan.intensities = raw.intensity;
  return scan;
}

std::expected<void, Rejection> checkWorldScan(const PointCloud& points_world,
                                              const Point3f& origin_world,
                                              const ScanLimits& limits) {
  if (points_world.empty()) return reject(RejectReason::kEmpty, "scan has no points");
  if (auto ok = checkCount(points_world.size(), limits); !ok) return ok;
  for (int axis = 0; axis < 3; ++axis) {
    if (auto ok = checkPosition(origin_world[axis], limits); !ok) return ok;
  }
  for (std::size_t i = 0; i < points_world.size(); ++i) {
    if (!points_world[i].allFinite()) {
      return reject(RejectReason::kNonFinitePoint, "point " + std::to_string(i) + " is NaN or Inf");
    }
  }
  return {};
}

}  // namespace densemap
