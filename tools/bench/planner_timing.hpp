#pragma once

// densemap-bench --esdf: what planner queries cost on the final map, beside the same questions
// asked as box queries (what a client without them sends).
#include <string>
#include <vector>

#include "densemap/planner/distance_field.hpp"
#include "densemap/query/map_view.hpp"
#include "lane.hpp"

namespace densemap::bench {

/// Times, on `view` and its `field` (the same version), on `threads` threads:
/// - a batch of 10,000 distances (with gradients and nearest obstacles) at points within 5 m
///   of the scans' origins, and the same points asked as box queries (the cube of the maximum
///   distance around each point, counting its occupied cells: the least a client needs to
///   bound a distance without the field);
/// - a 50 m path of radius 0.3 m along the scans' origins (back and forth when they span
///   less), and the same path asked as box queries (a cube of the radius every cell of arc).
/// Each `repeats` times; a table of p50 / p99 ms per query.
[[nodiscard]] std::string timePlannerQueries(const MapView& view, const DistanceField& field,
                                             const std::vector<WorldScan>& scans, int threads,
                                             int repeats = 20);

}  // namespace densemap::bench
