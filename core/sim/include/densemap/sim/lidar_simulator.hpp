#pragma once

#include <cstdint>

#include "densemap/io/scan.hpp"
#include "densemap/sim/lidar_model.hpp"
#include "densemap/sim/scene.hpp"

namespace densemap {

/// Casts every beam of one revolution into the scene from `T_world_sensor` and returns the
/// returns in the sensor frame (beam-major within each column, columns in azimuth order;
/// intensity = beam index). Lost beams (no surface within range, dropouts) give no point.
/// Deterministic for (seed, scan id) whatever the number of TBB threads: each column draws
/// from its own generator. Runs in the caller's task arena.
[[nodiscard]] Scan simulateScan(const Scene& scene, const LidarModel& lidar,
                                const Transform& T_world_sensor, std::size_t scan_id,
                                std::uint64_t seed);

}  // namespace densemap
