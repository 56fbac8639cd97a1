#include "block_logits.hpp"

#include <gtest/gtest.h>

#include <bit>
#include <cmath>
#include <cstdint>
#include <limits>
#include <random>
#include <vector>

namespace densemap::kernel {
namespace {

/// The published log-odds as written out: float(log(p / (1 - p))), p from the prior and the
/// cell's evidence (0.5 for an unknown cell).
float plainLogit(bool known, float alpha, float beta, double prior) {
  double p = 0.5;
  if (known) {
    const double a = prior + alpha;
    const double b = prior + beta;
    p = a / (a + b);
  }
  return static_cast<float>(std::log(p / (1.0 - p)));
}

std::uint32_t bitsOf(float v) { return std::bit_cast<std::uint32_t>(v); }

// blockLogits (AVX-512 lanes where the processor has them) against the definition written out,
// bit for bit, on evidence from zero to 1e30, equal pairs (p = 0.5) and several priors, with
// random known and asked cells.
TEST(BlockLogits, EqualTheDefinitionBitForBit) {
  std::mt19937_64 rng(71);
  std::uniform_real_distribution<double> exponent(-30.0, 30.0);
  std::uniform_real_distribution<float> small(0.0F, 10.0F);
  std::uniform_int_distribution<int> kind(0, 4);
  std::size_t compared = 0;
  for (const double prior : {0.001, 0.01, 0.5, 1.0}) {
    for (int round = 0; round < 200; ++round) {
      std::array<float, block::kVoxels> alpha{}, beta{}, out{};
      block::BlockMask known{}, cells{};
      for (int c = 0; c < block::kVoxels; ++c) {
        const auto draw = [&] {
          switch (kind(rng)) {
            case 0:
              return 0.0F;
            case 1:
              return static_cast<float>(std::pow(10.0, exponent(rng)));
            case 2:
              return std::floor(small(rng));
            default:
              return small(rng);
          }
        };
        alpha[c] = draw();
        beta[c] = kind(rng) == 0 ? alpha[c] : draw();
        if (rng() % 4 != 0) block::setBit(known, c);
        if (rng() % 3 != 0) block::setBit(cells, c);
      }
      out.fill(-7.0F);  // cells not asked keep it
      blockLogits(alpha, beta, known, cells, prior, out);
      for (int c = 0; c < block::kVoxels; ++c) {
        if (!block::testBit(cells, c)) {
          ASSERT_EQ(out[c], -7.0F) << "cell " << c << " was not asked";
          continue;
        }
        const float want = plainLogit(block::testBit(known, c), alpha[c], beta[c], prior);
        ASSERT_EQ(bitsOf(out[c]), bitsOf(want))
            << "alpha " << alpha[c] << " beta " << beta[c] << " prior " << prior << ": " << out[c]
            << " against " << want;
        ASSERT_EQ(bitsOf(cellLogit(alpha[c], beta[c], prior)),
                  bitsOf(plainLogit(true, alpha[c], beta[c], prior)));
        ++compared;
      }
    }
  }
  EXPECT_GT(compared, 200000U);
}

// floatLogs against float(std::log(x)) where the two are most likely to differ: x whose
// logarithm lies within a few units in the last place of a tie between two floats (those go
// to std::log), and over the whole range of doubles, zero, negatives, infinities, NaN and
// subnormals.
TEST(FloatLogs, EqualStdLogNearFloatTiesAndEverywhere) {
  std::mt19937_64 rng(72);
  std::uniform_real_distribution<float> value(-700.0F, 700.0F);
  std::uniform_int_distribution<int> nudge(-3, 3);
  std::vector<double> ties;
  for (int i = 0; i < 20000; ++i) {
    const float f = value(rng);
    // The tie above f: exact in double (a float has 24 significant bits).
    const double tie = (static_cast<double>(f) +
                        static_cast<double>(std::nextafter(f, std::numeric_limits<float>::max()))) /
                       2.0;
    double x = std::exp(tie);
    for (int k = nudge(rng); k != 0; k += k > 0 ? -1 : 1) {
      x = std::nextafter(x, k > 0 ? std::numeric_limits<double>::max() : 0.0);
    }
    if (std::isfinite(x) && x > 0.0) ties.push_back(x);
  }
  std::vector<float> out(ties.size());
  const std::size_t scalar = floatLogs(ties, out);
  for (std::size_t i = 0; i < ties.size(); ++i) {
    ASSERT_EQ(bitsOf(out[i]), bitsOf(static_cast<float>(std::log(ties[i])))) << ties[i];
  }
  if (hasLogLanes()) {
    // Nearly all of them are within the margin of a tie: the check sends them to std::log.
    EXPECT_GT(scalar, ties.size() * 9 / 10);
  }

  std::uniform_real_distribution<double> exponent(-300.0, 300.0);
  std::vector<double> any;
  for (int i = 0; i < 200000; ++i) any.push_back(std::pow(10.0, exponent(rng)));
  for (const double x :
       {0.0, -0.0, -1.0, 1.0, std::nextafter(1.0, 0.0), std::nextafter(1.0, 2.0),
        std::numeric_limits<double>::min(), std::numeric_limits<double>::max(),
        std::numeric_limits<double>::denorm_min(), 1e-310, std::numeric_limits<double>::infinity(),
        std::numeric_limits<double>::quiet_NaN(), 0.5, 2.0, std::sqrt(2.0)}) {
    any.push_back(x);
  }
  out.assign(any.size(), 0.0F);
  const std::size_t scalar_any = floatLogs(any, out);
  for (std::size_t i = 0; i < any.size(); ++i) {
    const float want = static_cast<float>(std::log(any[i]));
    if (std::isnan(want)) {
      ASSERT_TRUE(std::isnan(out[i])) << any[i];
    } else {
      ASSERT_EQ(bitsOf(out[i]), bitsOf(want)) << any[i];
    }
  }
  if (hasLogLanes()) {
    // Elsewhere the lanes answer: std::log only for the rare near-tie and the special values.
    EXPECT_LT(scalar_any, any.size() / 100);
  }
}

}  // namespace
}  // namespace densemap::kernel
