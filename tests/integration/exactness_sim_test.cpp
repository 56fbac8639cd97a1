// The raycast integrator equals OctoMap cell for cell on simulated sequences: 16/64/128 beams,
// indoor and outdoor, several resolutions, noise and dropouts, both backends, 1 and 2 threads.
#include <gtest/gtest.h>

#include "densemap/sim/sequence.hpp"
#include "densemap/test_support/data_dir.hpp"
#include "exactness_harness.hpp"

namespace densemap {
namespace {

struct SimCase {
  std::string scene;
  std::string sensor;
  int columns;
  double resolution;
  double max_range;
  double noise;
};

class RaycastOnSimulatedSequences : public ::testing::TestWithParam<SimCase> {};

TEST_P(RaycastOnSimulatedSequences, EqualsOctomapAfterEveryScan) {
  const SimCase c = GetParam();
  test::TempDir dir;
  SequenceOptions o;
  o.scene = c.scene;
  o.sensor = c.sensor;
  o.columns = c.columns;
  o.noise_std_m = c.noise;
  o.dropout = c.noise > 0 ? 0.05 : 0.0;
  o.scans = 4;
  o.seed = 42;
  o.ground_truth_resolution_m = 0;
  ASSERT_TRUE(writeSimulatedSequence(o, dir.path()));
  auto source = openScanSource(dir.path());
  ASSERT_TRUE(source);
  test::expectRaycastEqualsOctomap(test::loadWorldScans(**source, 0, 4), c.resolution, c.max_range);
}

INSTANTIATE_TEST_SUITE_P(Sequences, RaycastOnSimulatedSequences,
                         ::testing::Values(SimCase{"indoor", "vlp16", 900, 0.05, 10.0, 0.0},
                                           SimCase{"indoor", "os128", 512, 0.1, -1.0, 0.01},
                                           SimCase{"outdoor", "hdl64", 1024, 0.2, 40.0, 0.0},
                                           SimCase{"outdoor", "vlp16", 1800, 0.4, 80.0, 0.02},
                                           SimCase{"outdoor", "os128", 256, 0.1, 25.0, 0.0}),
                         [](const ::testing::TestParamInfo<SimCase>& param_info) {
                           const SimCase& c = param_info.param;
                           return c.scene + "_" + c.sensor + "_" +
                                  std::to_string(static_cast<int>(c.resolution * 100)) + "cm" +
                                  (c.noise > 0 ? "_noisy" : "");
                         });

}  // namespace
}  // namespace densemap
