// Every integration method equals OctoMap cell for cell (rule "set") and the plain per-ray
// result (rule "per_ray") after every scan on simulated sequences: 16/64/128 beams, indoor and
// outdoor, 0.05-0.4 m, noise and dropouts, both backends, 1 and 2 threads.
#include <gtest/gtest.h>

#include "densemap/sim/sequence.hpp"
#include "densemap/test_support/data_dir.hpp"
#include "simulated_scans.hpp"

namespace densemap {
namespace {

struct SimCase {
  std::string scene;
  std::string sensor;
  int columns;
  double resolution;
  double max_range;
  double noise;
  bool groups = true;  // enough points per voxel for super rays (not 16 beams at 5 cm)
};

class MethodsOnSimulatedSequences : public ::testing::TestWithParam<SimCase> {};

TEST_P(MethodsOnSimulatedSequences, EqualReferenceAfterEveryScan) {
  const SimCase c = GetParam();
  test::TempDir dir;
  SequenceOptions o;
  o.scene = c.scene;
  o.sensor = c.sensor;
  o.columns = c.columns;
  o.noise_std_m = c.noise;
  o.dropout = c.noise > 0 ? 0.05 : 0.0;
  o.scans = 6;
  o.seed = 42;
  o.ground_truth_resolution_m = 0;
  // A robot that stands still for its first scans (so free cells saturate and the culling
  // region grows), then drives on.
  const auto loaded = test::simulatedWorldScans(o, dir.path());
  ASSERT_EQ(loaded.size(), 6U);
  std::vector<test::WorldScan> scans(7, loaded[0]);
  scans.insert(scans.end(), loaded.begin() + 1, loaded.end());
  test::expectMethodsAgree(scans, c.resolution, c.max_range, 1, test::standardCases(), c.groups);
}

INSTANTIATE_TEST_SUITE_P(Sequences, MethodsOnSimulatedSequences,
                         ::testing::Values(SimCase{"indoor", "vlp16", 900, 0.05, 10.0, 0.0, false},
                                           SimCase{"indoor", "os128", 512, 0.1, -1.0, 0.01},
                                           SimCase{"outdoor", "hdl64", 1024, 0.2, 40.0, 0.0},
                                           SimCase{"outdoor", "vlp16", 1800, 0.4, 80.0, 0.02},
                                           SimCase{"outdoor", "os128", 256, 0.1, 25.0, 0.0, false}),
                         [](const ::testing::TestParamInfo<SimCase>& param_info) {
                           const SimCase& c = param_info.param;
                           return c.scene + "_" + c.sensor + "_" +
                                  std::to_string(static_cast<int>(c.resolution * 100)) + "cm" +
                                  (c.noise > 0 ? "_noisy" : "");
                         });

}  // namespace
}  // namespace densemap
