#include "query_room.hpp"

#include <algorithm>
#include <cmath>
#include <string>
#include <vector>

#include "densemap/parallel/tbb_runner.hpp"
#include "densemap/planner/distance_query.hpp"
#include "densemap/planner/swept_volume.hpp"
#include "densemap/query/map_queries.hpp"
#include "densemap/wire/topics.hpp"
#include "densemap_msgs.h"

namespace densemap::server {

namespace {

// Requests copied out of DDS's loans, answered later by a query task.
struct PointRequest {
  densemap_msgs_RequestId id;
  std::vector<float> xyz;
};
struct BboxRequest {
  densemap_msgs_RequestId id;
  Point3f min, max;
  std::uint32_t max_centers;
};
struct RayRequest {
  densemap_msgs_RequestId id;
  Point3f origin, direction;
  float max_range;
};
struct DistanceRequest {
  densemap_msgs_RequestId id;
  std::vector<float> xyz;
  DistanceQueryOptions options;
};
struct PathRequest {
  densemap_msgs_RequestId id;
  std::vector<float> xyz;
  double radius;
};
struct BoxesRequest {
  densemap_msgs_RequestId id;
  std::vector<float> floats;  // kBoxFloats a box
};
struct DistanceBoxRequest {
  densemap_msgs_RequestId id;
  Point3f min, max;
  bool unknown_as_occupied;
};

/// Distances from the field and the view it was updated to (one version), or why not.
void answerDistances(const Ingest& ingest, const dds::Entity& writer, const DistanceRequest& req,
                     std::string& error) {
  densemap_msgs_DistanceQueryReply rep{};
  rep.id = req.id;
  DistanceQueryResult result;
  const bool kept = ingest.withDistanceField([&](const DistanceField& field, const MapView& view) {
    rep.map_version = view.version();
    rep.max_distance = static_cast<float>(field.maxDistance());
    auto r = queryDistances(field, view, req.xyz, req.options, dds::kMaxQueryPoints, tbbRunner());
    if (r) {
      result = std::move(*r);
    } else {
      error = r.error().message;
    }
  });
  if (!kept) error = "this server keeps no distance field (config: esdf { enabled: true })";
  rep.status = error.empty() ? kOk : kInvalid;
  rep.error = const_cast<char*>(error.c_str());
  rep.distances = dds::borrowSequence<dds_sequence_float>(result.distances);
  rep.gradients = dds::borrowSequence<dds_sequence_float>(result.gradients);
  rep.nearest = dds::borrowSequence<dds_sequence_float>(result.nearest);
  (void)dds::write(writer, &rep);
}

void toWire(const SweptConflict& c, densemap_msgs_PathConflict& out) {
  for (int i = 0; i < 3; ++i) out.center[i] = c.center[i];
  out.arc_length = c.arc_length;
  out.segment = static_cast<std::uint32_t>(c.index);
}

void answerPath(const dds::Entity& writer, const PathRequest& req, const MapView& view,
                std::string& error) {
  densemap_msgs_PathQueryReply rep{};
  rep.id = req.id;
  rep.map_version = view.version();
  SweptVolumeLimits limits;
  limits.max_vertices = dds::kMaxPathVertices;
  auto result = checkPath(view, req.xyz, req.radius, limits);
  if (result) {
    rep.state = static_cast<std::uint8_t>(result->state);
    rep.has_occupied = result->occupied.has_value();
    if (result->occupied) toWire(*result->occupied, rep.occupied);
    rep.has_unknown = result->unknown.has_value();
    if (result->unknown) toWire(*result->unknown, rep.unknown);
    rep.length = result->length_m;
  } else {
    error = result.error().message;
  }
  rep.status = error.empty() ? kOk : kInvalid;
  rep.error = const_cast<char*>(error.c_str());
  (void)dds::write(writer, &rep);
}

void answerBoxes(const dds::Entity& writer, const BoxesRequest& req, const MapView& view,
                 std::string& error) {
  densemap_msgs_BoxesQueryReply rep{};
  rep.id = req.id;
  rep.map_version = view.version();
  auto boxes = boxesFromFloats(req.floats, dds::kMaxQueryBoxes);
  SweptVolumeLimits limits;
  limits.max_boxes = dds::kMaxQueryBoxes;
  auto result = boxes ? checkBoxes(view, *boxes, limits)
                      : Expected<SweptVolumeResult>(std::unexpected(boxes.error()));
  if (result) {
    rep.state = static_cast<std::uint8_t>(result->state);
    rep.has_occupied = result->occupied.has_value();
    if (result->occupied) toWire(*result->occupied, rep.occupied);
    rep.has_unknown = result->unknown.has_value();
    if (result->unknown) toWire(*result->unknown, rep.unknown);
  } else {
    error = result.error().message;
  }
  rep.status = error.empty() ? kOk : kInvalid;
  rep.error = const_cast<char*>(error.c_str());
  (void)dds::write(writer, &rep);
}

/// A dense box of the field and the view it was updated to (one version), or why not.
void answerDistanceBox(const Ingest& ingest, const dds::Entity& writer,
                       const DistanceBoxRequest& req, std::string& error) {
  densemap_msgs_DistanceBoxReply rep{};
  rep.id = req.id;
  DistanceBox box;
  const bool kept = ingest.withDistanceField([&](const DistanceField& field, const MapView& view) {
    rep.map_version = view.version();
    rep.max_distance = static_cast<float>(field.maxDistance());
    auto r = exportDistanceBox(field, view, req.min, req.max, req.unknown_as_occupied,
                               dds::kMaxDistanceBoxCells);
    if (r) {
      box = std::move(*r);
      const Point3f first = view.grid().keyToPoint(box.min);
      for (int i = 0; i < 3; ++i) {
        rep.min_center[i] = first[i];
        rep.size[i] = box.size[static_cast<std::size_t>(i)];
      }
    } else {
      error = r.error().message;
    }
  });
  if (!kept) error = "this server keeps no distance field (config: esdf { enabled: true })";
  rep.status = error.empty() ? kOk : kInvalid;
  rep.error = const_cast<char*>(error.c_str());
  rep.distances = dds::borrowSequence<dds_sequence_float>(box.distances);
  (void)dds::write(writer, &rep);
}

/// The cells of the box [min, max] at `resolution`, capped at `cap` (0 for a box that is not
/// finite or inverted: exportDistanceBox says why).
std::size_t boxCells(const Point3f& min, const Point3f& max, double resolution, std::size_t cap) {
  double cells = 1.0;
  for (int i = 0; i < 3; ++i) {
    if (!std::isfinite(min[i]) || !std::isfinite(max[i]) || min[i] > max[i]) return 0;
    cells *= std::floor(max[i] / resolution) - std::floor(min[i] / resolution) + 1.0;
  }
  return cells >= static_cast<double>(cap) ? cap : static_cast<std::size_t>(cells);
}

void answerPoints(const dds::Entity& writer, const PointRequest& req, const MapView& view,
                  std::string& error) {
  densemap_msgs_PointQueryReply rep{};
  rep.id = req.id;
  rep.map_version = view.version();
  auto result = queryPoints(view, req.xyz, dds::kMaxQueryPoints, tbbRunner());
  if (!result) {
    error = result.error().message;
    result = PointQueryResult{};
  }
  rep.status = error.empty() ? kOk : kInvalid;
  rep.error = const_cast<char*>(error.c_str());
  rep.log_odds = dds::borrowSequence<dds_sequence_float>(result->log_odds);
  rep.state = dds::borrowSequence<dds_sequence_octet>(result->states);
  (void)dds::write(writer, &rep);
}

void answerBox(const dds::Entity& writer, const BboxRequest& req, const MapView& view,
               std::size_t max_cells, std::string& error) {
  densemap_msgs_BboxQueryReply rep{};
  rep.id = req.id;
  rep.map_version = view.version();
  auto result = queryBox(view, req.min, req.max, max_cells,
                         std::min<std::uint32_t>(req.max_centers, 1'000'000));
  std::vector<float> centers;
  if (result) {
    rep.occupied = result->occupied;
    rep.free_cells = result->free;
    rep.unknown = result->unknown;
    for (const auto& c : result->occupied_centers)
      centers.insert(centers.end(), {c.x(), c.y(), c.z()});
  } else {
    error = result.error().message;
  }
  rep.status = error.empty() ? kOk : kInvalid;
  rep.error = const_cast<char*>(error.c_str());
  rep.occupied_centers = dds::borrowSequence<dds_sequence_float>(centers);
  (void)dds::write(writer, &rep);
}

void answerRay(const dds::Entity& writer, const RayRequest& req, const MapView& view,
               std::string& error) {
  densemap_msgs_RayQueryReply rep{};
  rep.id = req.id;
  rep.map_version = view.version();
  auto result = castRay(view, req.origin, req.direction, req.max_range);
  if (result) {
    rep.hit = result->hit;
    for (int i = 0; i < 3; ++i) rep.hit_point[i] = result->hit_center[i];
    rep.distance = result->distance;
  } else {
    error = result.error().message;
  }
  rep.status = error.empty() ? kOk : kInvalid;
  rep.error = const_cast<char*>(error.c_str());
  (void)dds::write(writer, &rep);
}

/// Why a point request is refused before it is read (empty: it is taken): more points than one
/// request may hold, or more bytes than the whole request budget.
std::string pointRefusal(std::size_t points, std::size_t bytes, std::size_t budget) {
  if (points > dds::kMaxQueryPoints) {
    return std::to_string(points) + " query points in one request: at most " +
           std::to_string(dds::kMaxQueryPoints) +
           " (densemap's client library splits larger batches)";
  }
  if (bytes > budget) {
    return std::to_string(points) + " query points need " + std::to_string(bytes >> 20) +
           " MiB, over the server's request budget of " + std::to_string(budget >> 20) +
           " MiB (pipeline.request_budget_mb): send smaller batches";
  }
  return {};
}

}  // namespace

std::size_t QueryRoom::distanceRequestBytes(std::size_t coordinates) {
  // The request's copy, the reply's 7 floats a point, and the DDS sample written.
  return coordinates * sizeof(float) + coordinates / 3 * 2 * 7 * sizeof(float);
}

std::size_t QueryRoom::pointRequestBytes(std::size_t coordinates) {
  // The request's copy (12 bytes a point), the reply's values and states (5 bytes a point) and
  // the DDS sample written (about as much again).
  return coordinates * sizeof(float) + coordinates / 3 * 2 * (sizeof(float) + 1);
}

void QueryRoom::take() {
  // Each request becomes a task answered from the latest version when it runs; the task reads
  // one view throughout, so a multi-cell answer is one consistent version.
  auto spawn = [this](auto answer, std::size_t bytes = 0) {
    tasks_.run(
        [this, answer = std::move(answer)] {
          std::string error;
          answer(*ingest_.view(), error);
          if (!error.empty()) stats_.refused(error);
          stats_.answered();
        },
        bytes);
  };
  // Take one request at a time from each reader in turn, so no kind starves the others. Each
  // reply waits (at most kAskerWait) until its writer has matched the asker's reply reader:
  // discovery is not symmetric, and a reply written before that match is lost (a one-shot
  // client would time out although the server had answered).
  const auto asker = [](const dds::Entity& reader, const dds_sample_info_t& info) {
    return dds::participantOfWriter(reader, info.publication_handle);
  };
  // A request refused before it is taken: its reply (`rep`, a reply type's empty value) says
  // why, once the asker can hear it; counted.
  const auto refuse = [&](auto rep, const dds::Entity& writer, const dds::Entity& reader,
                          const dds_sample_info_t& info, const densemap_msgs_RequestId& id,
                          const std::string& refusal) {
    rep.id = id;
    rep.status = kInvalid;
    rep.error = const_cast<char*>(refusal.c_str());
    replies_.awaitAsker(writer, asker(reader, info));
    (void)dds::write(writer, &rep);
    stats_.refused(refusal);
  };
  // Requests in flight share one memory budget (pipeline.request_budget_mb): while it is spent,
  // new requests wait in DDS (bounded by the readers' depth); one that could never fit is refused.
  bool took = true;
  while (took && tasks_.roomForMore()) {
    took = dds::takeOneWithInfo<densemap_msgs_PointQueryRequest>(
        readers_.point,
        [&](const densemap_msgs_PointQueryRequest& m, const dds_sample_info_t& info) {
          const std::size_t bytes = pointRequestBytes(m.points._length);
          const std::string refusal =
              pointRefusal(m.points._length / 3, bytes, tasks_.budgetBytes());
          if (!refusal.empty()) {
            if (const auto w = replies_.writer(ReplyTopic::kPoint, m.id.client_id)) {
              refuse(densemap_msgs_PointQueryReply{}, *w, readers_.point, info, m.id, refusal);
            } else {
              stats_.refused(refusal);
            }
            return;
          }
          PointRequest req{
              m.id, std::vector<float>(m.points._buffer, m.points._buffer + m.points._length)};
          const auto w = replies_.writer(ReplyTopic::kPoint, m.id.client_id);
          if (!w) return;
          spawn(
              [this, w, req = std::move(req), who = asker(readers_.point, info)](
                  const MapView& view, std::string& error) {
                replies_.awaitAsker(*w, who);
                answerPoints(*w, req, view, error);
              },
              bytes);
        });
    took |= dds::takeOneWithInfo<densemap_msgs_BboxQueryRequest>(
        readers_.bbox, [&](const densemap_msgs_BboxQueryRequest& m, const dds_sample_info_t& info) {
          BboxRequest req{m.id, toPoint(m.min), toPoint(m.max), m.max_centers};
          const auto w = replies_.writer(ReplyTopic::kBbox, m.id.client_id);
          if (!w) return;
          spawn([this, w, req, who = asker(readers_.bbox, info)](const MapView& view,
                                                                 std::string& error) {
            replies_.awaitAsker(*w, who);
            answerBox(*w, req, view, max_query_cells_, error);
          });
        });
    took |= dds::takeOneWithInfo<densemap_msgs_RayQueryRequest>(
        readers_.ray, [&](const densemap_msgs_RayQueryRequest& m, const dds_sample_info_t& info) {
          RayRequest req{m.id, toPoint(m.origin), toPoint(m.direction), m.max_range};
          const auto w = replies_.writer(ReplyTopic::kRay, m.id.client_id);
          if (!w) return;
          spawn([this, w, req, who = asker(readers_.ray, info)](const MapView& view,
                                                                std::string& error) {
            replies_.awaitAsker(*w, who);
            answerRay(*w, req, view, error);
          });
        });
    took |= dds::takeOneWithInfo<densemap_msgs_DistanceQueryRequest>(
        readers_.distance,
        [&](const densemap_msgs_DistanceQueryRequest& m, const dds_sample_info_t& info) {
          const auto w = replies_.writer(ReplyTopic::kDistance, m.id.client_id);
          if (!w) return;
          const std::size_t bytes = distanceRequestBytes(m.points._length);
          std::string refusal = pointRefusal(m.points._length / 3, bytes, tasks_.budgetBytes());
          if (!refusal.empty()) {
            refuse(densemap_msgs_DistanceQueryReply{}, *w, readers_.distance, info, m.id, refusal);
            return;
          }
          DistanceRequest req{
              m.id,
              std::vector<float>(m.points._buffer, m.points._buffer + m.points._length),
              {.unknown_as_occupied = m.unknown_as_occupied,
               .interpolate = m.interpolate,
               .nearest = m.nearest}};
          spawn(
              [this, w, req = std::move(req), who = asker(readers_.distance, info)](
                  const MapView&, std::string& error) {
                replies_.awaitAsker(*w, who);
                answerDistances(ingest_, *w, req, error);
              },
              bytes);
        });
    took |= dds::takeOneWithInfo<densemap_msgs_PathQueryRequest>(
        readers_.path, [&](const densemap_msgs_PathQueryRequest& m, const dds_sample_info_t& info) {
          const auto w = replies_.writer(ReplyTopic::kPath, m.id.client_id);
          if (!w) return;
          if (m.vertices._length / 3 > dds::kMaxPathVertices) {
            const std::string refusal = "path of " + std::to_string(m.vertices._length / 3) +
                                        " vertices, more than the " +
                                        std::to_string(dds::kMaxPathVertices) + " allowed";
            refuse(densemap_msgs_PathQueryReply{}, *w, readers_.path, info, m.id, refusal);
            return;
          }
          PathRequest req{
              m.id, std::vector<float>(m.vertices._buffer, m.vertices._buffer + m.vertices._length),
              m.radius};
          const std::size_t bytes = req.xyz.size() * sizeof(float);
          spawn(
              [this, w, req = std::move(req), who = asker(readers_.path, info)](
                  const MapView& view, std::string& error) {
                replies_.awaitAsker(*w, who);
                answerPath(*w, req, view, error);
              },
              bytes);
        });
    took |= dds::takeOneWithInfo<densemap_msgs_BoxesQueryRequest>(
        readers_.boxes,
        [&](const densemap_msgs_BoxesQueryRequest& m, const dds_sample_info_t& info) {
          const auto w = replies_.writer(ReplyTopic::kBoxes, m.id.client_id);
          if (!w) return;
          if (m.boxes._length / kBoxFloats > dds::kMaxQueryBoxes) {
            const std::string refusal = std::to_string(m.boxes._length / kBoxFloats) +
                                        " boxes, more than the " +
                                        std::to_string(dds::kMaxQueryBoxes) + " allowed";
            refuse(densemap_msgs_BoxesQueryReply{}, *w, readers_.boxes, info, m.id, refusal);
            return;
          }
          BoxesRequest req{m.id,
                           std::vector<float>(m.boxes._buffer, m.boxes._buffer + m.boxes._length)};
          const std::size_t bytes = req.floats.size() * sizeof(float);
          spawn(
              [this, w, req = std::move(req), who = asker(readers_.boxes, info)](
                  const MapView& view, std::string& error) {
                replies_.awaitAsker(*w, who);
                answerBoxes(*w, req, view, error);
              },
              bytes);
        });
    took |= dds::takeOneWithInfo<densemap_msgs_DistanceBoxRequest>(
        readers_.distance_box,
        [&](const densemap_msgs_DistanceBoxRequest& m, const dds_sample_info_t& info) {
          const auto w = replies_.writer(ReplyTopic::kDistanceBox, m.id.client_id);
          if (!w) return;
          DistanceBoxRequest req{m.id, toPoint(m.min), toPoint(m.max), m.unknown_as_occupied};
          const std::size_t bytes = distanceBoxBytes(boxCells(
              req.min, req.max, ingest_.view()->grid().resolution(), dds::kMaxDistanceBoxCells));
          if (bytes > tasks_.budgetBytes()) {
            const std::string refusal = "a distance box needing " + std::to_string(bytes >> 20) +
                                        " MiB, over the server's request budget of " +
                                        std::to_string(tasks_.budgetBytes() >> 20) +
                                        " MiB (pipeline.request_budget_mb): ask for smaller boxes";
            refuse(densemap_msgs_DistanceBoxReply{}, *w, readers_.distance_box, info, m.id,
                   refusal);
            return;
          }
          spawn(
              [this, w, req, who = asker(readers_.distance_box, info)](const MapView&,
                                                                       std::string& error) {
                replies_.awaitAsker(*w, who);
                answerDistanceBox(ingest_, *w, req, error);
              },
              bytes);
        });
  }
}

}  // namespace densemap::server
