#pragma once

#include "densemap/geometry/error.hpp"
#include "densemap/io/raw_scan.hpp"
#include "densemap/wire/dds.hpp"

struct densemap_msgs_PoseCorrection;

namespace densemap::dds {

/// Writes `correction` on densemap/pose_correction (the writer of Topics::pose_correction).
/// An error, nothing written, for more than kMaxCorrectedPoses poses.
[[nodiscard]] Expected<void> writePoseCorrection(const Entity& writer,
                                                 const PoseCorrection& correction);

/// A correction as it came off the wire: more than kMaxCorrectedPoses poses is an error before
/// anything is copied; the poses themselves are the reader's to check (checkCorrection).
[[nodiscard]] Expected<PoseCorrection> correctionFromWire(const densemap_msgs_PoseCorrection& msg);

}  // namespace densemap::dds
