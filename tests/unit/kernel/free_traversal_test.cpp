// FreeTraversal: each capsule's voxels and their kernel values, against a plain
// evaluation of every voxel of its box.

#include <gtest/gtest.h>

#include <algorithm>
#include <bit>
#include <cmath>
#include <limits>
#include <map>
#include <random>
#include <vector>

#include "densemap/geometry/block_layout.hpp"
#include "densemap/kernel/kernel_function.hpp"
#include "free_traversal.hpp"
#include "segment_voxels.hpp"

namespace densemap::kernel {
namespace {

/// Every voxel within reach * radius of each extent gets weight / evidenceShare(reach) *
/// k(d / radius): every voxel of the extent's box tested with the segment's distance.
std::map<std::uint64_t, double> plainSums(const VoxelGrid& grid,
                                          const std::vector<FreeExtent>& extents, double reach) {
  std::map<std::uint64_t, double> sums;
  const double compensation = 1.0 / FreeTraversal::evidenceShare(reach);
  for (const FreeExtent& e : extents) {
    const double r = reach * e.radius_m;
    const Eigen::Vector3d seg = e.to - e.from;
    test::forEachVoxelOfSegmentBox(grid, e.from, e.to, r, [&](const VoxelKey& k, double d) {
      // An open end: nothing beyond it along the line.
      const Eigen::Vector3d c(grid.keyToCoord(k[0]), grid.keyToCoord(k[1]), grid.keyToCoord(k[2]));
      const double t = (c - e.from).dot(seg) / seg.squaredNorm();
      if ((e.open_from && t < 0.0) || (e.open_to && t > 1.0)) return;
      if (d < r) sums[k.packed()] += e.weight * compensation * sparseKernel(d / e.radius_m);
    });
  }
  return sums;
}

/// Short capsules (a ray's tip: their box a few voxels, tested whole) and long ones (slice by
/// slice, their ends' slices with the segment's distance), every direction, radii below and
/// above a voxel, some with open ends: the same voxels as the plain evaluation, each within the
/// fixed point's and the table's rounding of its value.
TEST(FreeTraversal, ShortAndLongCapsulesGiveEveryVoxelInReachTheKernelOfItsDistance) {
  std::mt19937 rng(29);
  std::uniform_real_distribution<double> unit(-1.0, 1.0);
  for (const double resolution : {0.2, 0.1, 0.07}) {
    for (const double reach : {0.85, 1.0}) {
      const VoxelGrid grid(resolution);
      std::vector<FreeExtent> extents;
      for (int i = 0; i < 400; ++i) {
        const Eigen::Vector3d from(3.0 * unit(rng), 3.0 * unit(rng), 1.0 * unit(rng));
        Eigen::Vector3d dir(unit(rng), unit(rng), unit(rng));
        if (i % 5 == 0) dir[i % 3] = 0.0;  // in a plane of the grid
        dir.normalize();
        // Half tips (0.05-0.3 m), half free extents (0.3-6 m); radii 0.1 and 0.15-0.3 m.
        const bool tip = i % 2 == 0;
        const double length =
            tip ? 0.05 + 0.25 * (0.5 + 0.5 * unit(rng)) : 0.3 + 5.7 * (0.5 + 0.5 * unit(rng));
        const double radius = tip ? 0.1 : 0.15 + 0.075 * (1.0 + unit(rng));
        extents.push_back({from, from + length * dir, radius, 0.5 + 0.25 * (1.0 + unit(rng))});
        // A quarter of them open at one end or both (joints of the tree of bundles).
        extents.back().open_from = i % 4 == 1 || i % 8 == 3;
        extents.back().open_to = i % 4 == 3;
      }
      FreeTraversal traversal;
      const std::size_t visits = traversal.accumulate(grid, extents, reach);
      const std::map<std::uint64_t, double> plain = plainSums(grid, extents, reach);
      std::map<std::uint64_t, double> fast;
      for (const FreeTraversal::Block* b : traversal.blocks()) {
        block::forEachSetBit(b->mask, [&](int cell) {
          fast[block::keyOf(b->key, cell).packed()] =
              b->sum[static_cast<std::size_t>(cell)] / traversal.scale();
        });
      }
      SCOPED_TRACE("resolution " + std::to_string(resolution) + ", reach " + std::to_string(reach));
      ASSERT_GT(plain.size(), 2000U);
      EXPECT_GE(visits, fast.size());
      // A voxel at the very edge of the reach (its distance within rounding of it) may be in one
      // and not the other, with a value near 0: at most one in 1,000.
      std::size_t missing = 0, extra = 0;
      for (const auto& [key, value] : plain) {
        const auto it = fast.find(key);
        if (it == fast.end()) {
          ++missing;
          continue;
        }
        // The fixed point rounds each visit by at most half a unit.
        EXPECT_NEAR(it->second, value, 1e-6 * std::max(1.0, value) + 0.5 * 400 / traversal.scale());
      }
      for (const auto& entry : fast) extra += plain.count(entry.first) == 0 ? 1 : 0;
      EXPECT_LE(missing, plain.size() / 1000);
      EXPECT_LE(extra, plain.size() / 1000);
    }
  }
}

/// A capsule cut at a joint into two pieces open there gives every voxel what the whole one
/// gives it: each voxel's nearest point of the line lies on one piece or the other.
TEST(FreeTraversal, TwoPiecesOpenAtTheirJointGiveTheWholeCapsulesSums) {
  std::mt19937 rng(31);
  std::uniform_real_distribution<double> unit(-1.0, 1.0);
  const VoxelGrid grid(0.1);
  std::vector<FreeExtent> whole, pieces;
  for (int i = 0; i < 200; ++i) {
    const Eigen::Vector3d from(2.0 * unit(rng), 2.0 * unit(rng), 0.5 * unit(rng));
    const Eigen::Vector3d to =
        from + (1.0 + 2.0 * (1.0 + unit(rng))) *
                   Eigen::Vector3d(unit(rng), unit(rng), unit(rng)).normalized();
    const Eigen::Vector3d joint = from + (0.3 + 0.2 * (1.0 + unit(rng))) * (to - from);
    whole.push_back({from, to, 0.15, 1.0});
    pieces.push_back({from, joint, 0.15, 1.0, false, true});
    pieces.push_back({joint, to, 0.15, 1.0, true, false});
  }
  const auto sums = [&](const std::vector<FreeExtent>& extents) {
    FreeTraversal traversal;
    traversal.accumulate(grid, extents, 0.85);
    std::map<std::uint64_t, double> out;
    for (const FreeTraversal::Block* b : traversal.blocks()) {
      block::forEachSetBit(b->mask, [&](int cell) {
        out[block::keyOf(b->key, cell).packed()] =
            b->sum[static_cast<std::size_t>(cell)] / traversal.scale();
      });
    }
    return out;
  };
  const auto a = sums(whole), b = sums(pieces);
  ASSERT_GT(a.size(), 5000U);
  // A voxel whose nearest point is the joint itself (within rounding) may be counted by both.
  std::size_t differing = 0;
  for (const auto& [key, value] : a) {
    const auto it = b.find(key);
    differing += it == b.end() || std::abs(it->second - value) > 1e-5 ? 1 : 0;
  }
  EXPECT_LE(differing, a.size() / 1000);
  EXPECT_EQ(a.size(), b.size());
}

/// A block's sums as free evidence in lanes (where the processor has AVX-512) and cell by
/// cell: the same beta bit for bit and the same known cells.
TEST(FreeTraversal, EvidenceInLanesEqualsCellByCell) {
  std::mt19937_64 rng(33);
  std::uniform_int_distribution<std::int32_t> sum(0, std::numeric_limits<std::int32_t>::max());
  std::uniform_real_distribution<float> beta(0.0F, 50.0F);
  std::uniform_int_distribution<int> shift(0, 30);
  for (int round = 0; round < 300; ++round) {
    FreeTraversal::Block b;
    for (int c = 0; c < block::kVoxels; ++c) {
      b.sum[static_cast<std::size_t>(c)] = sum(rng) >> shift(rng);
      if (rng() % 3 != 0) block::setBit(b.mask, c);
    }
    const double inverse_scale = std::ldexp(1.0, -shift(rng));
    std::array<float, block::kVoxels> lanes{}, one_by_one{};
    for (float& v : lanes) v = beta(rng);
    one_by_one = lanes;
    block::BlockMask known_lanes{}, known_one{};
    known_lanes[static_cast<std::size_t>(round % block::kMaskWords)] = rng();
    known_one = known_lanes;
    FreeTraversal::addEvidence(b, inverse_scale, lanes, known_lanes, true);
    FreeTraversal::addEvidence(b, inverse_scale, one_by_one, known_one, false);
    for (int c = 0; c < block::kVoxels; ++c) {
      const auto i = static_cast<std::size_t>(c);
      ASSERT_EQ(std::bit_cast<std::uint32_t>(lanes[i]), std::bit_cast<std::uint32_t>(one_by_one[i]))
          << "cell " << c;
    }
    ASSERT_EQ(known_lanes, known_one);
  }
}

}  // namespace
}  // namespace densemap::kernel
