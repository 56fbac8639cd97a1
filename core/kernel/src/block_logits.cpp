#include "block_logits.hpp"

#include <algorithm>
#include <bit>
#include <cmath>
#include <cstdint>
#include <limits>

#if defined(__x86_64__) && defined(__GNUC__)
#include <immintrin.h>

#include <numbers>

#include "densemap/traversal/ray_traversal.hpp"  // hasWideLanes
#define DENSEMAP_LOG_LANES 1
#endif

namespace densemap::kernel {
namespace {

/// float(std::log(x)): what the lanes reproduce.
float floatLog(double x) { return static_cast<float>(std::log(x)); }

/// p / (1 - p), p = (prior + alpha) / (2 prior + alpha + beta): the cell's odds.
double oddsOf(float alpha, float beta, double prior) {
  const double a = prior + alpha;
  const double b = prior + beta;
  const double p = a / (a + b);
  return p / (1.0 - p);
}

#ifdef DENSEMAP_LOG_LANES
// ln 2 = kLn2Hi + kLn2Lo to about 2^-74: kLn2Hi has 21 significant bits, so e * kLn2Hi is
// exact for every exponent e of a double.
constexpr double kLn2Hi = 0x1.62e42p-1;
constexpr double kLn2Lo = 0x1.fdf473de6af28p-22;
/// Units in the last place of the double result within which of a float tie a lane goes to
/// std::log: the polynomial's error is a few units and std::log's under one, so beyond this
/// both round to the same float (ties are the only places where rounding to float jumps).
constexpr std::int64_t kTieMargin = std::int64_t{1} << 12;

/// ln x of eight positive normal doubles, within a few units in the last place: x = m 2^e with
/// m in [sqrt(1/2), sqrt(2)], ln m = 2 atanh(s) with s = (m - 1) / (m + 1), |s| <= 0.172, by
/// the series 2 s (1 + s^2/3 + ... + s^20/21) (the next term is below 2^-56 of the sum).
[[gnu::target("avx512f,avx512dq"), gnu::always_inline]] inline __m512d lnLanes(__m512d x) {
  __m512d e = _mm512_maskz_getexp_pd(0xff, x);
  __m512d m = _mm512_maskz_getmant_pd(0xff, x, _MM_MANT_NORM_1_2, _MM_MANT_SIGN_src);
  const __mmask8 high = _mm512_cmp_pd_mask(m, _mm512_set1_pd(std::numbers::sqrt2), _CMP_GT_OQ);
  m = _mm512_mask_mul_pd(m, high, m, _mm512_set1_pd(0.5));
  e = _mm512_mask_add_pd(e, high, e, _mm512_set1_pd(1.0));
  const __m512d one = _mm512_set1_pd(1.0);
  const __m512d s = _mm512_div_pd(_mm512_sub_pd(m, one), _mm512_add_pd(m, one));
  const __m512d z = _mm512_mul_pd(s, s);
  __m512d series = _mm512_set1_pd(1.0 / 21.0);
  for (int k = 9; k >= 0; --k) {
    series = _mm512_fmadd_pd(series, z, _mm512_set1_pd(1.0 / (2 * k + 1)));
  }
  const __m512d ln_m = _mm512_mul_pd(_mm512_add_pd(s, s), series);
  return _mm512_add_pd(_mm512_mul_pd(e, _mm512_set1_pd(kLn2Hi)),
                       _mm512_fmadd_pd(e, _mm512_set1_pd(kLn2Lo), ln_m));
}

/// float(std::log(x)) for the lanes of `lanes` into out[0, 8) (other lanes untouched); returns
/// how many went to std::log.
[[gnu::target("avx512f,avx512dq,avx512vl"), gnu::always_inline]] inline std::size_t floatLogLanes(
    __m512d x, __mmask8 lanes, float* out) {
  const __mmask8 normal =
      _mm512_cmp_pd_mask(x, _mm512_set1_pd(std::numeric_limits<double>::min()), _CMP_GE_OQ) &
      _mm512_cmp_pd_mask(x, _mm512_set1_pd(std::numeric_limits<double>::max()), _CMP_LE_OQ);
  const __m512d y = lnLanes(_mm512_mask_blend_pd(normal, _mm512_set1_pd(1.0), x));
  // A float keeps the top 23 of a double's 52 fraction bits: a tie has the 29 below at 2^28.
  const __m512i low =
      _mm512_and_si512(_mm512_castpd_si512(y), _mm512_set1_epi64((std::int64_t{1} << 29) - 1));
  const __m512i off =
      _mm512_maskz_abs_epi64(0xff, _mm512_sub_epi64(low, _mm512_set1_epi64(1LL << 28)));
  const __mmask8 near_tie = _mm512_cmplt_epi64_mask(off, _mm512_set1_epi64(kTieMargin));
  _mm256_mask_storeu_ps(out, lanes, _mm512_maskz_cvtpd_ps(0xff, y));
  const auto scalar = static_cast<unsigned>(lanes & (near_tie | static_cast<__mmask8>(~normal)));
  if (scalar == 0) return 0;
  alignas(64) double xs[8];
  _mm512_store_pd(xs, x);
  for (unsigned c = scalar; c != 0; c &= c - 1) {
    const int k = std::countr_zero(c);
    out[k] = floatLog(xs[k]);
  }
  return static_cast<std::size_t>(std::popcount(scalar));
}

[[gnu::target("avx512f,avx512dq,avx512vl")]] void blockLogitsWide(
    const std::array<float, block::kVoxels>& alpha, const std::array<float, block::kVoxels>& beta,
    const block::BlockMask& known, const block::BlockMask& cells, double prior,
    std::array<float, block::kVoxels>& out) {
  const __m512d prior_lanes = _mm512_set1_pd(prior);
  const __m512d one = _mm512_set1_pd(1.0);
  for (int g = 0; g < block::kVoxels / 8; ++g) {
    const int wd = g / 8, shift = 8 * (g % 8);
    const auto lanes = static_cast<__mmask8>(cells[static_cast<std::size_t>(wd)] >> shift);
    if (lanes == 0) continue;
    const auto kn = static_cast<__mmask8>(known[static_cast<std::size_t>(wd)] >> shift);
    // oddsOf, lane by lane (the same operations: IEEE results), 1 for an unknown cell.
    const __m512d a =
        _mm512_add_pd(prior_lanes, _mm512_maskz_cvtps_pd(0xff, _mm256_loadu_ps(&alpha[8 * g])));
    const __m512d b =
        _mm512_add_pd(prior_lanes, _mm512_maskz_cvtps_pd(0xff, _mm256_loadu_ps(&beta[8 * g])));
    const __m512d p = _mm512_div_pd(a, _mm512_add_pd(a, b));
    const __m512d odds = _mm512_mask_div_pd(one, kn, p, _mm512_sub_pd(one, p));
    (void)floatLogLanes(odds, lanes, &out[8 * g]);
  }
}

[[gnu::target("avx512f,avx512dq,avx512vl")]] std::size_t floatLogsWide(std::span<const double> x,
                                                                       std::span<float> out) {
  std::size_t scalar = 0;
  for (std::size_t i = 0; i < x.size(); i += 8) {
    const std::size_t n = std::min<std::size_t>(8, x.size() - i);
    const auto lanes = static_cast<__mmask8>((1U << n) - 1U);
    scalar += floatLogLanes(_mm512_maskz_loadu_pd(lanes, &x[i]), lanes, &out[i]);
  }
  return scalar;
}
#endif

}  // namespace

float cellLogit(float alpha, float beta, double prior) {
  return floatLog(oddsOf(alpha, beta, prior));
}

bool hasLogLanes() {
#ifdef DENSEMAP_LOG_LANES
  return hasWideLanes();
#else
  return false;
#endif
}

void blockLogits(const std::array<float, block::kVoxels>& alpha,
                 const std::array<float, block::kVoxels>& beta, const block::BlockMask& known,
                 const block::BlockMask& cells, double prior,
                 std::array<float, block::kVoxels>& out) {
#ifdef DENSEMAP_LOG_LANES
  if (hasLogLanes()) {
    blockLogitsWide(alpha, beta, known, cells, prior, out);
    return;
  }
#endif
  block::forEachSetBit(cells, [&](int cell) {
    const auto c = static_cast<std::size_t>(cell);
    out[c] = block::testBit(known, cell) ? cellLogit(alpha[c], beta[c], prior) : 0.0F;
  });
}

std::size_t floatLogs(std::span<const double> x, std::span<float> out) {
#ifdef DENSEMAP_LOG_LANES
  if (hasLogLanes()) return floatLogsWide(x, out);
#endif
  for (std::size_t i = 0; i < x.size(); ++i) out[i] = floatLog(x[i]);
  return x.size();
}

}  // namespace densemap::kernel
