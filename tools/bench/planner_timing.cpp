#include "planner_timing.hpp"

#include <tbb/task_arena.h>

#include <chrono>
#include <cstdio>
#include <random>

#include "densemap/geometry/percentile.hpp"
#include "densemap/parallel/tbb_runner.hpp"
#include "densemap/planner/distance_query.hpp"
#include "densemap/planner/swept_volume.hpp"
#include "densemap/query/map_queries.hpp"

namespace densemap::bench {

namespace {

/// `f` run `repeats` times: each run's ms.
template <class F>
std::vector<double> timed(int repeats, F&& f) {
  std::vector<double> ms;
  for (int i = 0; i < repeats; ++i) {
    const auto t0 = std::chrono::steady_clock::now();
    f();
    ms.push_back(
        std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - t0).count());
  }
  return ms;
}

/// A path of `length` metres along the origins, back and forth as often as needed.
std::vector<float> pathAlong(const std::vector<WorldScan>& scans, double length) {
  std::vector<Point3f> stops;
  for (const auto& s : scans) stops.push_back(s.origin);
  std::vector<float> xyz{stops[0].x(), stops[0].y(), stops[0].z()};
  double done = 0.0;
  std::size_t i = 0;
  int step = 1;
  Point3f at = stops[0];
  for (int guard = 0; done < length && stops.size() > 1 && guard < 1'000'000; ++guard) {
    if (i + step >= stops.size() || (step < 0 && i == 0)) step = -step;
    const Point3f next = stops[i + step];
    i += step;
    const double seg = (next - at).norm();
    if (seg <= 0.0) continue;
    const double take = std::min(seg, length - done);
    const Point3f end = at + (next - at) * static_cast<float>(take / seg);
    xyz.insert(xyz.end(), {end.x(), end.y(), end.z()});
    done += take;
    at = end;
  }
  return xyz;
}

std::string row(const char* what, const std::vector<double>& ms, const char* note) {
  char line[200];
  std::snprintf(line, sizeof(line), "%-34s %9.3f %9.3f  %s\n", what, percentile(ms, 0.5),
                percentile(ms, 0.99), note);
  return line;
}

}  // namespace

std::string timePlannerQueries(const MapView& view, const DistanceField& field,
                               const std::vector<WorldScan>& scans, int threads, int repeats) {
  if (scans.empty()) return {};
  tbb::task_arena arena(threads);
  std::mt19937 rng(17);
  std::uniform_int_distribution<std::size_t> which(0, scans.size() - 1);
  std::uniform_real_distribution<float> around(-5.0F, 5.0F);
  std::vector<float> points;
  for (int i = 0; i < 10'000; ++i) {
    const Point3f o = scans[which(rng)].origin;
    points.insert(points.end(), {o.x() + around(rng), o.y() + around(rng), o.z() + around(rng)});
  }
  const std::vector<float> path = pathAlong(scans, 50.0);
  const double radius = 0.3;
  const float reach = static_cast<float>(field.maxDistance());
  std::string out;
  char head[200];
  std::snprintf(head, sizeof(head), "%-34s %9s %9s\n", "planner query (final map)", "p50 ms",
                "p99 ms");
  out += head;
  std::size_t within = 0;
  const auto distances = timed(repeats, [&] {
    arena.execute([&] {
      auto r = queryDistances(field, view, points, {}, 10'000, tbbRunner());
      within = 0;
      for (const float d : r->distances) within += d < reach ? 1 : 0;
    });
  });
  out += row("distance 10,000 points", distances, "distances, gradients, nearest obstacles");
  const auto bare = timed(repeats, [&] {
    arena.execute([&] {
      DistanceQueryOptions o;
      o.nearest = false;
      (void)queryDistances(field, view, points, o, 10'000, tbbRunner());
    });
  });
  out += row("distance 10,000, nearest off", bare,
             "nearest = false (the gradient still needs them)");
  const auto cautious = timed(repeats, [&] {
    arena.execute([&] {
      DistanceQueryOptions o;
      o.unknown_as_occupied = true;
      (void)queryDistances(field, view, points, o, 10'000, tbbRunner());
    });
  });
  out += row("distance 10,000, unknown occupied", cautious, "");
  const auto as_boxes = timed(std::max(1, repeats / 4), [&] {
    arena.execute([&] {
      tbbRunner().run(points.size() / 3, 256, [&](std::size_t begin, std::size_t end) {
        for (std::size_t i = begin; i != end; ++i) {
          const Point3f p(points[3 * i], points[3 * i + 1], points[3 * i + 2]);
          (void)queryBox(view, p - Point3f::Constant(reach), p + Point3f::Constant(reach),
                         50'000'000, 0);
        }
      });
    });
  });
  out += row("  the same as 10,000 box queries", as_boxes, "a cube of the maximum each");
  SweptVolumeResult answer;
  const auto path_ms = timed(repeats, [&] { answer = *checkPath(view, path, radius); });
  char note[160];
  std::snprintf(note, sizeof(note), "%zu vertices, %s", path.size() / 3,
                answer.state == CellState::kFree       ? "free"
                : answer.state == CellState::kOccupied ? "occupied"
                                                       : "unknown");
  out += row("path 50 m, radius 0.3 m", path_ms, note);
  const auto path_boxes = timed(repeats, [&] {
    const double res = view.grid().resolution();
    for (std::size_t v = 0; v + 1 < path.size() / 3; ++v) {
      const Point3f a(path[3 * v], path[3 * v + 1], path[3 * v + 2]);
      const Point3f b(path[3 * v + 3], path[3 * v + 4], path[3 * v + 5]);
      const auto steps = static_cast<int>(std::ceil((b - a).norm() / res));
      for (int s = 0; s <= steps; ++s) {
        const Point3f c =
            a + (b - a) * (static_cast<float>(s) / static_cast<float>(std::max(steps, 1)));
        (void)queryBox(view, c - Point3f::Constant(static_cast<float>(radius)),
                       c + Point3f::Constant(static_cast<float>(radius)), 50'000'000, 0);
      }
    }
  });
  out += row("  the same as box queries", path_boxes, "a cube of the radius every cell of arc");
  std::snprintf(note, sizeof(note), "(%zu of the 10,000 points within %.1f m of an obstacle)\n",
                within, static_cast<double>(reach));
  out += note;
  return out;
}

}  // namespace densemap::bench
