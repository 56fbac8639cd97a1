// Swept-volume checks against brute force: every cell of a random map is tested on its own
// (its distance to the path by ternary search over each segment, convex in the segment's
// parameter), and the answer (state, first occupied and unknown contact along the path) must
// be the one the brute force gives; oriented boxes against interval overlap (axis-aligned)
// and Dykstra's alternating projections (rotated). Requests past their bounds are refused.
#include "densemap/planner/swept_volume.hpp"

#include <gtest/gtest.h>

#include <cmath>
#include <random>

#include "densemap/map/grid_map.hpp"

namespace densemap {
namespace {

using Vec3 = Eigen::Vector3d;

double boxD2(const Vec3& p, const Vec3& lo, const Vec3& hi) {
  return (p - p.cwiseMax(lo).cwiseMin(hi)).squaredNorm();
}

/// min over s in [0, 1] of the squared distance from a + s (b - a) to the box, by ternary
/// search (the function is convex in s).
double segmentD2(const Vec3& a, const Vec3& b, const Vec3& lo, const Vec3& hi, double* at) {
  double l = 0.0, r = 1.0;
  for (int i = 0; i < 100; ++i) {
    const double m1 = l + (r - l) / 3, m2 = r - (r - l) / 3;
    if (boxD2(a + m1 * (b - a), lo, hi) <= boxD2(a + m2 * (b - a), lo, hi)) {
      r = m2;
    } else {
      l = m1;
    }
  }
  *at = 0.5 * (l + r);
  return boxD2(a + *at * (b - a), lo, hi);
}

TEST(SegmentBoxContact, MatchesTernarySearch) {
  std::mt19937 rng(1);
  std::uniform_real_distribution<double> u(-2.0, 2.0);
  for (int i = 0; i < 20000; ++i) {
    const Vec3 a(u(rng), u(rng), u(rng)), b(u(rng), u(rng), u(rng));
    const Vec3 c(u(rng) / 2, u(rng) / 2, u(rng) / 2);
    const Vec3 lo = c - Vec3::Constant(0.1), hi = c + Vec3::Constant(0.1);
    const double r = std::abs(u(rng));
    double at = 0;
    const double want = segmentD2(a, b, lo, hi, &at);
    const SegmentBoxContact got = segmentBoxContact(a, b, lo, hi, r * r);
    ASSERT_NEAR(got.min_d2, want, 1e-9) << i;
    ASSERT_EQ(got.first_s.has_value(), got.min_d2 <= r * r) << i;
    if (got.first_s) {
      EXPECT_LE(boxD2(a + *got.first_s * (b - a), lo, hi), r * r + 1e-12) << i;
      if (*got.first_s > 1e-9) {
        EXPECT_GT(boxD2(a + (*got.first_s - 1e-9) * (b - a), lo, hi), r * r - 1e-12) << i;
      }
    }
  }
}

/// A random map of occupied, free and unknown cells around the origin.
std::shared_ptr<const MapView> randomMap(double res, unsigned seed) {
  GridMap map(res, SensorModel{});
  std::mt19937 rng(seed);
  std::uniform_int_distribution<int> coord(32768 - 12, 32768 + 11);
  std::uniform_int_distribution<int> kind(0, 9);
  for (int z = 32768 - 12; z < 32768 + 12; ++z) {
    for (int y = 32768 - 12; y < 32768 + 12; ++y) {
      for (int x = 32768 - 12; x < 32768 + 12; ++x) {
        const int k = kind(rng);
        if (k == 0) continue;  // unknown
        map.setLogOdds(VoxelKey{static_cast<std::uint16_t>(x), static_cast<std::uint16_t>(y),
                                static_cast<std::uint16_t>(z)},
                       k == 1 ? 1.0F : -1.0F);
      }
    }
  }
  return MapView::fromMap(map, 1);
}

TEST(CheckPath, EqualsBruteForceOnRandomMapsAndPaths) {
  const double res = 0.1;
  std::mt19937 rng(7);
  std::uniform_real_distribution<double> u(-1.2, 1.2);
  std::uniform_real_distribution<double> radius(0.0, 0.25);
  std::size_t occupied_answers = 0, other_answers = 0;
  for (int trial = 0; trial < 50; ++trial) {
    const auto view = randomMap(res, static_cast<unsigned>(trial));
    const int vertices = 1 + trial % 4;
    std::vector<float> xyz;
    for (int i = 0; i < vertices; ++i) {
      for (int a = 0; a < 3; ++a) xyz.push_back(static_cast<float>(u(rng)));
    }
    const double r = trial % 5 == 0 ? 0.0 : radius(rng);
    auto got = checkPath(*view, xyz, r);
    ASSERT_TRUE(got) << got.error().message;
    // Brute force: every cell near the segment's box. Cells within a hair of the radius may
    // go either way (the check is conservative): `strict` leaves them out, `loose` counts them.
    struct Firsts {
      std::optional<double> occupied, unknown;
    } strict, loose;
    double arc = 0.0;
    const std::size_t n = xyz.size() / 3;
    for (std::size_t seg = 0; seg < std::max<std::size_t>(n - 1, 1); ++seg) {
      const Vec3 a(xyz[3 * seg], xyz[3 * seg + 1], xyz[3 * seg + 2]);
      const Vec3 b = n == 1 ? a : Vec3(xyz[3 * seg + 3], xyz[3 * seg + 4], xyz[3 * seg + 5]);
      const double len = (b - a).norm();
      const Vec3 near_lo = a.cwiseMin(b) - Vec3::Constant(r + res);
      const Vec3 near_hi = a.cwiseMax(b) + Vec3::Constant(r + res);
      for (int z = 32768 - 18; z < 32768 + 18; ++z) {
        for (int y = 32768 - 18; y < 32768 + 18; ++y) {
          for (int x = 32768 - 18; x < 32768 + 18; ++x) {
            const VoxelKey k{static_cast<std::uint16_t>(x), static_cast<std::uint16_t>(y),
                             static_cast<std::uint16_t>(z)};
            const Vec3 c = view->grid().keyToPoint(k).cast<double>();
            if ((c.array() < near_lo.array()).any() || (c.array() > near_hi.array()).any()) {
              continue;
            }
            const auto v = view->logOdds(k);
            if (v && *v < 0) continue;  // free
            const Vec3 lo = c - Vec3::Constant(res / 2), hi = c + Vec3::Constant(res / 2);
            double at = 0;
            const double d2 = segmentD2(a, b, lo, hi, &at);
            const double reach = r + 1e-5;
            if (d2 > reach * reach) continue;
            // The first contact: bisect between 0 and the closest point.
            auto first = [&](double within) {
              if (boxD2(a, lo, hi) <= within * within) return arc;
              double l = 0.0, h = at;
              for (int it = 0; it < 100; ++it) {
                const double m = 0.5 * (l + h);
                (boxD2(a + m * (b - a), lo, hi) <= within * within ? h : l) = m;
              }
              return arc + h * len;
            };
            auto keep = [&](std::optional<double>& f, double contact) {
              if (!f || contact < *f) f = contact;
            };
            keep(v ? loose.occupied : loose.unknown, first(reach));
            const bool clear = r == 0.0 ? d2 == 0.0 : d2 < (r - 1e-5) * (r - 1e-5);
            if (clear) keep(v ? strict.occupied : strict.unknown, first(r));
          }
        }
      }
      arc += len;
    }
    if (strict.occupied) {
      ++occupied_answers;
      EXPECT_EQ(got->state, CellState::kOccupied) << trial;
      ASSERT_TRUE(got->occupied) << trial;
      EXPECT_GE(got->occupied->arc_length, *loose.occupied - 1e-5) << trial;
      EXPECT_LE(got->occupied->arc_length, *strict.occupied + 1e-5) << trial;
      const auto k = view->grid().pointToKey(got->occupied->center);
      ASSERT_TRUE(k);
      EXPECT_GT(view->logOdds(*k).value_or(-1.0F), 0.0F) << trial;
    } else if (!loose.occupied) {
      ++other_answers;
      EXPECT_NE(got->state, CellState::kOccupied) << trial;
      if (strict.unknown) {
        EXPECT_EQ(got->state, CellState::kUnknown) << trial;
        ASSERT_TRUE(got->unknown) << trial;
        EXPECT_GE(got->unknown->arc_length, *loose.unknown - 1e-5) << trial;
        EXPECT_LE(got->unknown->arc_length, *strict.unknown + 1e-5) << trial;
      } else if (!loose.unknown) {
        EXPECT_EQ(got->state, CellState::kFree) << trial;
      }
    }
  }
  EXPECT_GT(occupied_answers, 10U);
  EXPECT_GT(other_answers, 3U);
}

/// Squared distance between the cell's cube and the oriented box, by Dykstra's alternating
/// projections (both convex).
double cubeBoxD2(const Vec3& c, double half, const OrientedBox& box) {
  const Eigen::Matrix3d rot = box.rotation.cast<double>().toRotationMatrix();
  const Vec3 bc = box.center.cast<double>(), e = box.half_extents.cast<double>();
  auto toCube = [&](const Vec3& p) {
    return p.cwiseMax(c - Vec3::Constant(half)).cwiseMin(c + Vec3::Constant(half));
  };
  auto toBox = [&](const Vec3& p) {
    const Vec3 local = rot.transpose() * (p - bc);
    return Vec3(bc + rot * local.cwiseMax(-e).cwiseMin(e));
  };
  Vec3 x = c, p = Vec3::Zero(), q = Vec3::Zero();
  Vec3 y = toBox(x);
  for (int i = 0; i < 500; ++i) {
    y = toBox(x + p);
    p = x + p - y;
    x = toCube(y + q);
    q = y + q - x;
  }
  return (toCube(y) - y).squaredNorm();
}

TEST(CheckBoxes, EqualsReferenceOnRandomBoxes) {
  const double res = 0.1;
  std::mt19937 rng(3);
  std::uniform_real_distribution<double> u(-0.8, 0.8);
  std::uniform_real_distribution<double> ext(0.0, 0.3);
  std::array<int, 3> answers{};
  for (int trial = 0; trial < 40; ++trial) {
    const auto view = randomMap(res, 100U + static_cast<unsigned>(trial));
    OrientedBox box;
    box.center =
        Point3f(static_cast<float>(u(rng)), static_cast<float>(u(rng)), static_cast<float>(u(rng)));
    box.half_extents = Point3f(static_cast<float>(ext(rng)), static_cast<float>(ext(rng)),
                               static_cast<float>(ext(rng)));
    if (trial % 2 == 1) {
      box.rotation = Eigen::Quaternionf(Eigen::AngleAxisf(
          static_cast<float>(u(rng) * 3), Eigen::Vector3f(u(rng), u(rng), 1).normalized()));
    }
    std::vector<OrientedBox> boxes{box};
    auto got = checkBoxes(*view, boxes);
    ASSERT_TRUE(got) << got.error().message;
    bool any_occupied = false, any_unknown = false;
    const Eigen::Matrix3d rot = box.rotation.cast<double>().toRotationMatrix();
    const Vec3 reach = rot.cwiseAbs() * box.half_extents.cast<double>() + Vec3::Constant(res);
    const Vec3 near_lo = box.center.cast<double>() - reach;
    const Vec3 near_hi = box.center.cast<double>() + reach;
    for (int z = 32768 - 20; z < 32768 + 20; ++z) {
      for (int y = 32768 - 20; y < 32768 + 20; ++y) {
        for (int x = 32768 - 20; x < 32768 + 20; ++x) {
          const VoxelKey k{static_cast<std::uint16_t>(x), static_cast<std::uint16_t>(y),
                           static_cast<std::uint16_t>(z)};
          const auto v = view->logOdds(k);
          if (v && *v < 0) continue;
          const Vec3 c = view->grid().keyToPoint(k).cast<double>();
          if ((c.array() < near_lo.array()).any() || (c.array() > near_hi.array()).any()) {
            continue;
          }
          const double d2 = cubeBoxD2(c, res / 2, box);
          if (d2 > 1e-10 && d2 < 1e-6) continue;  // touching within tolerance: either way
          if (d2 > 1e-10) continue;
          (v ? any_occupied : any_unknown) = true;
        }
      }
    }
    const CellState want = any_occupied  ? CellState::kOccupied
                           : any_unknown ? CellState::kUnknown
                                         : CellState::kFree;
    EXPECT_EQ(got->state, want) << trial;
    ++answers[static_cast<int>(want)];
  }
  EXPECT_GT(answers[static_cast<int>(CellState::kOccupied)], 5);
  EXPECT_GT(
      answers[static_cast<int>(CellState::kFree)] + answers[static_cast<int>(CellState::kUnknown)],
      2);
}

TEST(SweptVolume, RefusesRequestsPastTheirBounds) {
  const auto view = randomMap(0.1, 1);
  const float nan = std::nanf("");
  std::vector<float> path{0, 0, 0, 1, 1, 1};
  EXPECT_FALSE(checkPath(*view, path, -0.1));
  EXPECT_FALSE(checkPath(*view, path, std::nan("")));
  EXPECT_FALSE(checkPath(*view, std::vector<float>{0, 0, nan}, 0.1));
  EXPECT_FALSE(checkPath(*view, std::vector<float>{0, 0}, 0.1));
  EXPECT_FALSE(checkPath(*view, std::vector<float>{}, 0.1));
  EXPECT_FALSE(checkPath(*view, std::vector<float>(3'000'000, 0.0F), 0.1));  // 10^6 vertices
  EXPECT_FALSE(checkPath(*view, std::vector<float>{0, 0, 0, 9000, 0, 0, 0, 0, 0, 9000, 0, 0}, 0.1));
  EXPECT_FALSE(checkPath(*view, std::vector<float>{0, 0, 0, 1e9F, 0, 0}, 0.1));
  auto huge = checkPath(*view, std::vector<float>{0, 0, 0, 100, 0, 0}, 49.0);  // ~10^12 cells
  ASSERT_FALSE(huge);
  EXPECT_NE(huge.error().message.find("cells"), std::string::npos) << huge.error().message;
  EXPECT_TRUE(checkPath(*view, path, 0.3));
  OrientedBox bad;
  bad.half_extents = Point3f(-1, 0, 0);
  EXPECT_FALSE(checkBoxes(*view, std::vector<OrientedBox>{bad}));
  bad.half_extents = Point3f(0.1F, 0.1F, 0.1F);
  bad.rotation = Eigen::Quaternionf(2, 0, 0, 0);
  EXPECT_FALSE(checkBoxes(*view, std::vector<OrientedBox>{bad}));
  bad.rotation = Eigen::Quaternionf::Identity();
  bad.center = Point3f(nan, 0, 0);
  EXPECT_FALSE(checkBoxes(*view, std::vector<OrientedBox>{bad}));
  EXPECT_FALSE(checkBoxes(*view, std::vector<OrientedBox>{}));
}

}  // namespace
}  // namespace densemap

namespace densemap {
namespace {

TEST(BoxFloats, RoundTripAndRefuseBadLengths) {
  OrientedBox a;
  a.center = Point3f(1.5F, -2.0F, 0.25F);
  a.half_extents = Point3f(0.5F, 0.25F, 1.0F);
  a.rotation = Eigen::Quaternionf(Eigen::AngleAxisf(0.7F, Eigen::Vector3f(0, 0.6F, 0.8F)));
  OrientedBox b;
  std::vector<float> floats;
  appendBoxFloats(a, floats);
  appendBoxFloats(b, floats);
  ASSERT_EQ(floats.size(), 2 * kBoxFloats);
  auto back = boxesFromFloats(floats, 2);
  ASSERT_TRUE(back);
  ASSERT_EQ(back->size(), 2U);
  EXPECT_EQ((*back)[0].center, a.center);
  EXPECT_EQ((*back)[0].half_extents, a.half_extents);
  EXPECT_EQ((*back)[0].rotation.coeffs(), a.rotation.coeffs());
  EXPECT_EQ((*back)[1].rotation.coeffs(), b.rotation.coeffs());
  EXPECT_FALSE(boxesFromFloats(floats, 1)) << "more boxes than allowed";
  EXPECT_FALSE(boxesFromFloats(std::span<const float>(floats).first(15), 2)) << "a partial box";
  EXPECT_FALSE(boxesFromFloats({}, 2)) << "no box";
}

}  // namespace
}  // namespace densemap
