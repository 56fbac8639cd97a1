#pragma once

#include <array>
#include <cstddef>
#include <span>

#include "densemap/geometry/block_layout.hpp"

namespace densemap::kernel {

/// The published log-odds of a dense map's known cell of evidence alpha and beta under
/// `prior`: float(log(p / (1 - p))), p = (prior + alpha) / (2 prior + alpha + beta). The one
/// definition; blockLogits computes it a block at a time, and gives an unknown cell 0 (p = 0.5).
[[nodiscard]] float cellLogit(float alpha, float beta, double prior);

/// cellLogit of each cell of `cells` into out[cell] (an unknown cell, not in `known`: 0), bit
/// for bit, eight cells at a time in AVX-512 lanes where the processor has them (hasLogLanes).
void blockLogits(const std::array<float, block::kVoxels>& alpha,
                 const std::array<float, block::kVoxels>& beta, const block::BlockMask& known,
                 const block::BlockMask& cells, double prior,
                 std::array<float, block::kVoxels>& out);

/// Whether blockLogits and floatLogs take AVX-512 lanes here.
[[nodiscard]] bool hasLogLanes();

/// out[i] = float(std::log(x[i])), bit for bit: in AVX-512 lanes where the processor has them,
/// a polynomial within a few units in the last place of ln x, rounded to float where that
/// rounding cannot differ from std::log's (farther than 2^12 units from a tie between two
/// floats); std::log itself for the other lanes and for x not a positive normal double.
/// Returns how many went to std::log. out.size() >= x.size().
std::size_t floatLogs(std::span<const double> x, std::span<float> out);

}  // namespace densemap::kernel
