#pragma once

#include <array>
#include <cstddef>
#include <string_view>

#include "densemap/geometry/error.hpp"
#include "densemap/io/raw_scan.hpp"
#include "densemap/io/scan.hpp"

namespace densemap {

/// Why a scan was refused; counted per reason in the server's status.
enum class RejectReason {
  kEmpty,
  kLengthNotMultipleOf3,
  kTooManyPoints,
  kIntensityLength,
  kNonFinitePoint,
  kBadQuaternion,
  kPoseOutOfBounds,
  /// The engine failed on a valid scan (out of memory, say): the scan is not integrated, the
  /// server goes on (Ingest).
  kInternal,
  /// A sensor id longer than kMaxSensorIdBytes (checked before the id is counted or queued).
  kSensorIdTooLong,
  kCount
};
inline constexpr std::size_t kRejectReasonCount = static_cast<std::size_t>(RejectReason::kCount);

[[nodiscard]] std::string_view rejectReasonName(RejectReason reason);

/// The longest sensor id a scan may carry, bytes: status replies and events echo it.
inline constexpr std::size_t kMaxSensorIdBytes = 256;

struct ScanLimits {
  std::size_t max_points = 2'000'000;
  /// The sensor must lie within this distance of the map origin on every axis (the map's
  /// addressable half-extent is a hard upper bound).
  double max_abs_position_m = 1000.0;
  /// |q| must be within this of 1.
  double quaternion_tolerance = 1e-3;
};

struct Rejection {
  RejectReason reason;
  std::string message;
};

/// A Rejection when `sensor_id` is longer than kMaxSensorIdBytes.
[[nodiscard]] std::expected<void, Rejection> checkSensorId(std::string_view sensor_id);

/// A sensor pose from outside (a scan's, a pose correction's): the quaternion's norm within
/// `limits.quaternion_tolerance` of 1, the position finite and within
/// `limits.max_abs_position_m` on every axis.
[[nodiscard]] std::expected<void, Rejection> checkScanPose(const std::array<double, 3>& t,
                                                           const std::array<double, 4>& q,
                                                           const ScanLimits& limits);

/// Checks a raw scan and turns it into a sensor-frame Scan, or says why not. Pure.
[[nodiscard]] std::expected<Scan, Rejection> validateScan(const RawScan& raw,
                                                          const ScanLimits& limits);

/// The same rules for a scan already in the world frame: at least one point, at most
/// `limits.max_points`, every point finite, the origin finite and within
/// `limits.max_abs_position_m` on every axis. Pure.
[[nodiscard]] std::expected<void, Rejection> checkWorldScan(const PointCloud& points_world,
                                                            const Point3f& origin_world,
                                                            const ScanLimits& limits);

}  // namespace densemap
