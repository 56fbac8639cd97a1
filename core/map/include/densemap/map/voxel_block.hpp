#pragma once

#include <array>
#include <cstdint>

#include "densemap/geometry/block_layout.hpp"

namespace densemap {

/// 8^3 voxels of float log-odds (OctoMap's own representation, so every update rounds as
/// OctoMap's does) and a bit per voxel saying whether it is known.
struct VoxelBlock {
  std::array<float, block::kVoxels> log_odds{};
  std::array<std::uint64_t, block::kMaskWords> known{};

  [[nodiscard]] bool isKnown(int index) const {
    return ((known[index >> 6] >> (index & 63)) & 1U) != 0;
  }
  void markKnown(int index) { known[index >> 6] |= std::uint64_t{1} << (index & 63); }
};

/// A dense kernel map's evidence in one block: per cell Beta(alpha, beta) beyond the
/// prior, float (a scan's kernels are summed in double, then added: half the memory of double,
/// and a Beta posterior's mean does not need more digits), and a bit per cell that any kernel
/// reached. It lives with the block's entry in the BlockStore, beside the published log-odds.
struct BlockEvidence {
  std::array<float, block::kVoxels> alpha{};
  std::array<float, block::kVoxels> beta{};
  block::BlockMask known{};
};

}  // namespace densemap
