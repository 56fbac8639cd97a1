#include "densemap/map/occupancy_decay.hpp"

#include <gtest/gtest.h>

#include <cmath>
#include <vector>

#include "densemap/map/grid_map.hpp"

namespace densemap {
namespace {

constexpr std::int64_t kSecond = 1'000'000'000;

/// A cell's value after `steps` decay steps from `v`, one miss at a time, or NaN once it is no
/// longer occupied: the rule written out plainly.
float steppedPlainly(const SensorModel& model, float v, int steps) {
  for (int s = 0; s < steps; ++s) {
    v = model.updateBy(v, model.miss());
    if (!(v > 0.0F)) return std::nanf("");
  }
  return v;
}

struct Fixture {
  SensorModel model;
  GridMap map{0.2, model};
  OccupancyDecay decay{DecayOptions{.after_s = 1.0, .period_s = 0.5}};
  const VoxelKey a{32768, 32768, 32768};
  const VoxelKey b{32769, 32768, 32768};  // same block as a
  const VoxelKey far{32768 + 64, 32768, 32768};
};

TEST(OccupancyDecay, StepsOccupiedCellsAtTheirRateUntilUnknown) {
  Fixture f;
  f.map.setLogOdds(f.a, f.model.clampMax());
  f.map.setLogOdds(f.b, f.model.hit());
  const std::vector<VoxelKey> hits{f.a, f.b};
  f.decay.observe(hits, 0);
  EXPECT_EQ(f.decay.trackedBlocks(), 1U);

  // Not yet due: nothing changes.
  CellChanges changes;
  auto stats = f.decay.decay(f.map, kSecond - 1'000'000, &changes);
  EXPECT_EQ(stats.stepped + stats.erased, 0U);
  EXPECT_TRUE(changes.empty());

  // Due at 1 s: one step each; b (one hit, 0.85) stays occupied after one miss (0.44).
  stats = f.decay.decay(f.map, kSecond, &changes);
  EXPECT_EQ(stats.stepped, 2U);
  EXPECT_EQ(*f.map.logOdds(f.a), steppedPlainly(f.model, f.model.clampMax(), 1));
  EXPECT_EQ(*f.map.logOdds(f.b), steppedPlainly(f.model, f.model.hit(), 1));
  EXPECT_EQ(changes.size(), 2U);

  // 1.2 s later: 2 more periods elapsed plus the one due at 1.5 s... steps due at 1.5, 2.0 s.
  changes.clear();
  stats = f.decay.decay(f.map, 2 * kSecond + kSecond / 5, &changes);
  EXPECT_EQ(*f.map.logOdds(f.a), steppedPlainly(f.model, f.model.clampMax(), 3));
  EXPECT_FALSE(f.map.logOdds(f.b).has_value()) << "b left the occupied class: unknown";
  EXPECT_EQ(stats.erased, 1U);
  ASSERT_EQ(changes.size(), 2U);
  EXPECT_EQ(f.map.knownCells(), 1U);

  // Long after: a is gone too; its block (no known cell left) with it; nothing is tracked.
  stats = f.decay.decay(f.map, 60 * kSecond, &changes);
  EXPECT_FALSE(f.map.logOdds(f.a).has_value());
  EXPECT_EQ(f.map.knownCells(), 0U);
  EXPECT_EQ(f.map.writerStore().latest(block::blockOf(f.a)), nullptr);
  EXPECT_EQ(f.decay.trackedBlocks(), 0U);
}

TEST(OccupancyDecay, AHitStartsTheWaitAgain) {
  Fixture f;
  f.map.setLogOdds(f.a, f.model.clampMax());
  f.decay.observe(std::vector<VoxelKey>{f.a}, 0);
  f.decay.observe(std::vector<VoxelKey>{f.a}, kSecond * 9 / 10);
  auto stats = f.decay.decay(f.map, kSecond * 18 / 10);
  EXPECT_EQ(stats.stepped, 0U) << "due at 1.9 s, not 1.0 s";
  EXPECT_EQ(*f.map.logOdds(f.a), f.model.clampMax());
  stats = f.decay.decay(f.map, kSecond * 19 / 10);
  EXPECT_EQ(stats.stepped, 1U);
}

TEST(OccupancyDecay, FreeAndForgottenCellsAreLetGo) {
  Fixture f;
  f.map.setLogOdds(f.a, f.model.clampMax());
  f.map.setLogOdds(f.far, f.model.clampMax());
  f.decay.observe(std::vector<VoxelKey>{f.a, f.far}, 0);
  // Rays cleared a; far was erased by a command.
  f.map.setLogOdds(f.a, f.model.miss());
  f.map.erase(f.far);
  const std::size_t known = f.map.knownCells();
  CellChanges changes;
  const auto stats = f.decay.decay(f.map, 5 * kSecond, &changes);
  EXPECT_EQ(stats.stepped + stats.erased, 0U);
  EXPECT_TRUE(changes.empty());
  EXPECT_EQ(*f.map.logOdds(f.a), f.model.miss()) << "a free cell does not decay";
  EXPECT_EQ(f.map.knownCells(), known);
  EXPECT_EQ(f.decay.trackedBlocks(), 0U);
}

TEST(OccupancyDecay, TheClockNeverRunsBackAndLongGapsDecayAtOnce) {
  Fixture f;
  f.map.setLogOdds(f.a, f.model.clampMax());
  f.decay.observe(std::vector<VoxelKey>{f.a}, 100 * kSecond);
  // An older stamp counts as the latest: a is not due.
  EXPECT_EQ(f.decay.decay(f.map, 0).stepped, 0U);
  // 30 days on: every step due at once.
  const std::int64_t later = 100 * kSecond + std::int64_t{30} * 86400 * kSecond;
  const auto stats = f.decay.decay(f.map, later);
  EXPECT_EQ(stats.erased, 1U);
  EXPECT_FALSE(f.map.logOdds(f.a).has_value());
  // And a cell of the same block, hit now, waits its own time.
  f.map.setLogOdds(f.b, f.model.clampMax());
  f.decay.observe(std::vector<VoxelKey>{f.b}, later + kSecond);
  EXPECT_EQ(f.decay.decay(f.map, later + 2 * kSecond - 1).stepped, 0U);
  EXPECT_EQ(f.decay.decay(f.map, later + 2 * kSecond).stepped, 1U);
}

TEST(OccupancyDecay, ACellHitForMonthsKeepsItsTimes) {
  // Due times are kept as 32-bit milliseconds after a base per block: a cell re-hit for 60
  // days moves its block's base past that range, and its times stay right.
  SensorModel model;
  GridMap map(0.2, model);
  OccupancyDecay decay(DecayOptions{.after_s = 1e6, .period_s = 1.0});
  const VoxelKey a{32768, 32768, 32768};
  map.setLogOdds(a, model.clampMax());
  constexpr std::int64_t kDay = 86400 * kSecond;
  std::int64_t t = 0;
  for (int i = 0; i <= 12; ++i, t += 5 * kDay) {
    EXPECT_EQ(decay.decay(map, t).stepped, 0U) << "day " << i * 5;
    decay.observe(std::vector<VoxelKey>{a}, t);
  }
  t -= 5 * kDay;
  EXPECT_EQ(decay.decay(map, t + std::int64_t{1'000'000} * kSecond - 1'000'000).stepped, 0U);
  EXPECT_EQ(decay.decay(map, t + std::int64_t{1'000'000} * kSecond).stepped, 1U);
  EXPECT_EQ(*map.logOdds(a), steppedPlainly(model, model.clampMax(), 1));
}

TEST(OccupancyDecay, RefusesOptionsOutOfRange) {
  EXPECT_TRUE(checkDecayOptions({.after_s = 0.0, .period_s = 0.001}));
  EXPECT_FALSE(checkDecayOptions({.after_s = -1.0, .period_s = 1.0}));
  EXPECT_FALSE(checkDecayOptions({.after_s = NAN, .period_s = 1.0}));
  EXPECT_FALSE(checkDecayOptions({.after_s = 1.0, .period_s = 0.0}));
  EXPECT_FALSE(checkDecayOptions({.after_s = 1.0, .period_s = INFINITY}));
  EXPECT_FALSE(checkDecayOptions({.after_s = 2e6, .period_s = 1.0}));
}

}  // namespace
}  // namespace densemap
