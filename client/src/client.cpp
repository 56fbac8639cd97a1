#include "densemap/client/client.hpp"

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <optional>
#include <random>
#include <thread>
#include <unordered_map>

#include "client_parts.hpp"
#include "densemap/client/testing.hpp"
#include "densemap/planner/swept_volume.hpp"
#include "densemap/query/map_queries.hpp"
#include "densemap/query/version_delta.hpp"
#include "densemap/wire/correction_wire.hpp"
#include "densemap/wire/dds.hpp"
#include "densemap/wire/delta_wire.hpp"
#include "densemap/wire/status.hpp"
#include "densemap/wire/topics.hpp"
#include "densemap_msgs.h"
#include "map_snapshot_parts.hpp"

namespace densemap {

using namespace client_detail;

Client::Impl::Impl(const ClientOptions& options)
    : options_(options),
      dds_(std::make_unique<Dds>()),
      client_id_(std::random_device{}() * 4294967296ULL + std::random_device{}()) {}

Client::Client(std::vector<std::unique_ptr<Impl>> replicas) : impl_(std::move(replicas.front())) {
  for (std::size_t i = 1; i < replicas.size(); ++i) standby_.push_back(std::move(replicas[i]));
}

Client::~Client() = default;

Expected<std::unique_ptr<Client>> Client::create(const ClientOptions& options) {
  if (options.replicas.size() > 16) return makeError("at most 16 replicas to fail over to");
  std::vector<std::unique_ptr<Impl>> replicas;
  std::vector<std::string> names{options.instance};
  names.insert(names.end(), options.replicas.begin(), options.replicas.end());
  for (const std::string& name : names) {
    ClientOptions one = options;
    one.instance = name;
    one.replicas.clear();
    auto impl = Impl::create(one);
    if (!impl) return std::unexpected(impl.error());
    replicas.push_back(std::move(*impl));
  }
  return std::unique_ptr<Client>(new Client(std::move(replicas)));
}

Expected<std::unique_ptr<Client::Impl>> Client::Impl::create(const ClientOptions& options) {
  auto c = std::make_unique<Impl>(options);
  auto& d = *c->dds_;
  auto p = dds::createParticipant({options.domain_id, options.network_interface, options.security});
  if (!p) return std::unexpected(p.error());
  d.participant = std::move(*p);
  Expected<void> status;
  auto topics = dds::Topics::create(d.participant, options.instance);
  if (!topics) return std::unexpected(topics.error());
  d.topics = std::move(*topics);
  auto make = [&](dds::Entity& out, const dds::Entity& t, dds::QosSpec q, bool writer) {
    if (!status) return;
    auto e =
        writer ? dds::createWriter(d.participant, t, q) : dds::createReader(d.participant, t, q);
    if (e)
      out = std::move(*e);
    else if (!dds::isNotAllowedBySecurity(e.error()))
      status = std::unexpected(e.error());
  };
  const dds::QosSpec requests = dds::kRequestQos;
  make(d.scan_w, d.topics.scan, dds::kScanQos, true);
  make(d.pc_w, d.topics.pose_correction, dds::kCorrectionQos, true);
  make(d.pq_w, d.topics.point_request, requests, true);
  make(d.bq_w, d.topics.bbox_request, requests, true);
  make(d.rq_w, d.topics.ray_request, requests, true);
  make(d.dq_w, d.topics.distance_request, requests, true);
  make(d.paq_w, d.topics.path_request, requests, true);
  make(d.oq_w, d.topics.boxes_request, requests, true);
  make(d.dbq_w, d.topics.distance_box_request, requests, true);
  make(d.cq_w, d.topics.command_request, dds::kCommandQos, true);
  make(d.mq_w, d.topics.map_request, dds::kCommandQos, true);
  // Replies come in this client's own partition: the server writes each asker's replies with
  // writers made for it, so no other client receives (and discards) them.
  const std::string mine = dds::replyPartition(c->client_id_);
  dds::QosSpec replies = requests, command_replies = dds::kCommandQos;
  replies.partition = command_replies.partition = mine;
  make(d.pr_r, d.topics.point_reply, replies, false);
  make(d.br_r, d.topics.bbox_reply, replies, false);
  make(d.rr_r, d.topics.ray_reply, replies, false);
  make(d.dr_r, d.topics.distance_reply, replies, false);
  make(d.par_r, d.topics.path_reply, replies, false);
  make(d.or_r, d.topics.boxes_reply, replies, false);
  make(d.dbr_r, d.topics.distance_box_reply, replies, false);
  make(d.cr_r, d.topics.command_reply, command_replies, false);
  make(d.man_r, d.topics.manifest, dds::kLatestStateQos, false);
  if (options.subscribe_deltas) make(d.delta_r, d.topics.delta, dds::kDeltaReaderQos, false);
  make(d.event_r, d.topics.events, dds::kEventReaderQos, false);
  make(d.st_r, d.topics.status, dds::kLatestStateQos, false);
  if (!status) return std::unexpected(status.error());
  for (auto [ws, reader] :
       {std::pair{&d.pr_ws, &d.pr_r}, std::pair{&d.br_ws, &d.br_r}, std::pair{&d.rr_ws, &d.rr_r},
        std::pair{&d.dr_ws, &d.dr_r}, std::pair{&d.par_ws, &d.par_r}, std::pair{&d.or_ws, &d.or_r},
        std::pair{&d.dbr_ws, &d.dbr_r}, std::pair{&d.cr_ws, &d.cr_r}}) {
    if (reader->get() <= 0) continue;
    auto w = dds::WaitSet::create(d.participant);
    if (!w) return std::unexpected(w.error());
    if (auto ok = w->attachReader(*reader, 1); !ok) return std::unexpected(ok.error());
    ws->emplace(std::move(*w));
  }
  return c;
}

template <class F>
auto Client::failingOver(F&& ask) -> decltype(ask(std::declval<Impl&>())) {
  auto answer = ask(*impl_);
  for (std::size_t tried = 0; !answer && impl_->unanswered && tried < standby_.size(); ++tried) {
    // The server in use did not answer: the next replica serves this call and the later ones;
    // the silent one goes to the back of the line.
    standby_.push_back(std::move(impl_));
    impl_ = std::move(standby_.front());
    standby_.erase(standby_.begin());
    answer = ask(*impl_);
  }
  return answer;
}

Expected<void> Client::Impl::waitForServer() {
  const auto deadline = Clock::now() + options_.timeout;
  // The topics whose server side has not matched yet (empty: found).
  auto unmatched = [&] {
    std::vector<std::string> names;
    const auto topic_name = [](const dds::Entity& e) {
      char name[256] = "";
      (void)dds_get_name(dds_get_topic(e.get()), name, sizeof name);
      return std::string(name);
    };
    for (const dds::Entity* w :
         {&dds_->scan_w, &dds_->pq_w, &dds_->bq_w, &dds_->rq_w, &dds_->dq_w, &dds_->paq_w,
          &dds_->oq_w, &dds_->dbq_w, &dds_->cq_w, &dds_->mq_w}) {
      if (w->get() <= 0) continue;  // not granted by DDS Security
      dds_publication_matched_status_t s;
      if (dds_get_publication_matched_status(w->get(), &s) < 0 || s.current_count == 0)
        names.push_back(topic_name(*w));
    }
    // The reply readers match the server's writers for this client once it asks (the server
    // waits for that match before it replies).
    for (const dds::Entity* r : {&dds_->event_r, &dds_->delta_r}) {
      if (r->get() <= 0) continue;  // deltas not subscribed, or not granted
      dds_subscription_matched_status_t s;
      if (dds_get_subscription_matched_status(r->get(), &s) < 0 || s.current_count == 0)
        names.push_back(topic_name(*r));
    }
    return names;
  };
  for (auto missing = unmatched(); !missing.empty(); missing = unmatched()) {
    if (Clock::now() > deadline) {
      std::string list;
      for (const std::string& n : missing) list += (list.empty() ? "" : ", ") + n;
      return makeError("no densemap-server found on DDS domain " +
                       std::to_string(options_.domain_id) + " (interface " +
                       options_.network_interface + ") within " +
                       std::to_string(options_.timeout.count()) + " ms (unmatched: " + list + ")");
    }
    std::this_thread::sleep_for(std::chrono::milliseconds(10));
  }
  // The server builds deltas only while it sees a matched reader; its side of the match may
  // come a moment after ours.
  if (options_.subscribe_deltas) std::this_thread::sleep_for(std::chrono::milliseconds(200));
  return {};
}

Expected<void> Client::Impl::publishScan(const RawScan& scan) {
  densemap_msgs_Scan msg{};
  msg.sensor_id = const_cast<char*>(scan.sensor_id.c_str());
  msg.frame = const_cast<char*>("sensor");
  msg.seq = scan.seq;
  msg.stamp_ns = scan.stamp_ns;
  for (int i = 0; i < 3; ++i) msg.T_world_sensor.t[i] = scan.t_world_sensor[i];
  for (int i = 0; i < 4; ++i) msg.T_world_sensor.q[i] = scan.q_world_sensor[i];
  auto& xyz = const_cast<std::vector<float>&>(scan.xyz);
  auto& intensity = const_cast<std::vector<float>&>(scan.intensity);
  msg.points = dds::borrowSequence<dds_sequence_float>(xyz);
  msg.intensity = dds::borrowSequence<dds_sequence_float>(intensity);
  if (auto ok = permitted(dds_->scan_w, "publishing scans"); !ok)
    return std::unexpected(ok.error());
  return dds::write(dds_->scan_w, &msg);
}

Expected<void> Client::Impl::publishPoseCorrection(const PoseCorrection& correction) {
  if (auto ok = permitted(dds_->pc_w, "publishing pose corrections"); !ok) {
    return std::unexpected(ok.error());
  }
  return dds::writePoseCorrection(dds_->pc_w, correction);
}

namespace {

/// Waits for the reply to `id` on `reader` (asleep on `waitset` until samples arrive; replies
/// to other clients are taken and skipped), calling `f` with it.
template <class Reply>
Expected<void> awaitReply(const dds::Entity& reader, dds::WaitSet& waitset,
                          const densemap_msgs_RequestId& id, std::chrono::milliseconds timeout,
                          const std::function<void(const Reply&)>& f) {
  const auto deadline = Clock::now() + timeout;
  bool done = false;
  while (!done) {
    dds::takeAll<Reply>(reader, [&](const Reply& r) {
      if (!done && r.id.client_id == id.client_id && r.id.request_id == id.request_id) {
        f(r);
        done = true;
      }
    });
    if (done) break;
    const auto now = Clock::now();
    if (now > deadline)
      return makeError("no reply from densemap-server within " + std::to_string(timeout.count()) +
                       " ms");
    const auto left = std::chrono::duration_cast<std::chrono::milliseconds>(deadline - now);
    (void)waitset.wait(
        std::clamp(left, std::chrono::milliseconds(1), std::chrono::milliseconds(100)));
  }
  return {};
}

}  // namespace

template <class Reply, class Request, class Read>
Expected<void> Client::Impl::ask(const dds::Entity& writer, const dds::Entity& reader,
                                 std::optional<dds::WaitSet>& waitset, const Request& req,
                                 const char* what, Read&& read) {
  if (auto ok = permitted(writer, what); !ok) return std::unexpected(ok.error());
  if (auto ok = permitted(reader, what); !ok) return std::unexpected(ok.error());
  if (auto ok = dds::write(writer, &req); !ok) return std::unexpected(ok.error());
  std::string error;
  unanswered = false;
  auto ok = awaitReply<Reply>(reader, *waitset, req.id, options_.timeout, [&](const Reply& r) {
    if (r.status != 0) {
      error = text(r.error);
      return;
    }
    read(r, error);
  });
  if (!ok) {
    unanswered = true;
    return std::unexpected(ok.error());
  }
  if (!error.empty()) return makeError("server: " + error);
  return {};
}

Expected<PointQueryAnswer> Client::queryPoints(const std::vector<Point3f>& points_world) {
  std::vector<float> xyz;
  xyz.reserve(points_world.size() * 3);
  for (const auto& p : points_world) xyz.insert(xyz.end(), {p.x(), p.y(), p.z()});
  return failingOver([&](Impl& i) { return i.queryPointsRaw(xyz); });
}

Expected<PointQueryAnswer> Client::queryPoints(std::span<const float> xyz_world) {
  if (auto ok = checkPointCoordinates(xyz_world.size()); !ok) return std::unexpected(ok.error());
  return failingOver([&](Impl& i) { return i.queryPointsRaw(xyz_world); });
}

Expected<PointQueryAnswer> Client::Impl::queryPointsRaw(std::span<const float> xyz) {
  // At most kMaxQueryPoints a request (whole points; a stray coordinate goes with the last
  // part, for the server to refuse).
  constexpr std::size_t kPart = std::size_t{dds::kMaxQueryPoints} * 3;
  if (xyz.size() <= kPart + 2) return queryPointsOnce(xyz);
  PointQueryAnswer answer;
  answer.log_odds.reserve(xyz.size() / 3);
  answer.states.reserve(xyz.size() / 3);
  for (std::size_t from = 0; from < xyz.size(); from += kPart) {
    const std::size_t n = xyz.size() - from <= kPart + 2 ? xyz.size() - from : kPart;
    auto part = queryPointsOnce(std::span<const float>(xyz).subspan(from, n));
    if (!part) return part;
    answer.map_version = part->map_version;
    answer.log_odds.insert(answer.log_odds.end(), part->log_odds.begin(), part->log_odds.end());
    answer.states.insert(answer.states.end(), part->states.begin(), part->states.end());
    if (n != kPart) break;
  }
  return answer;
}

Expected<PointQueryAnswer> Client::Impl::queryPointsOnce(std::span<const float> xyz) {
  densemap_msgs_PointQueryRequest req{};
  req.id = {client_id_, next_request_++};
  req.points = dds::borrowSequence<dds_sequence_float>(xyz);
  PointQueryAnswer answer;
  auto ok = ask<densemap_msgs_PointQueryReply>(
      dds_->pq_w, dds_->pr_r, dds_->pr_ws, req, "point queries",
      [&](const densemap_msgs_PointQueryReply& r, std::string& /*error*/) {
        answer.map_version = r.map_version;
        for (std::uint32_t i = 0; i < r.log_odds._length; ++i) {
          const float v = r.log_odds._buffer[i];
          answer.log_odds.push_back(std::isnan(v) ? std::nullopt : std::optional<float>(v));
          answer.states.push_back(static_cast<CellState>(r.state._buffer[i]));
        }
      });
  if (!ok) return std::unexpected(ok.error());
  return answer;
}

Expected<BoxQueryAnswer> Client::Impl::queryBox(const Point3f& min, const Point3f& max,
                                                std::uint32_t max_centers) {
  densemap_msgs_BboxQueryRequest req{};
  req.id = {client_id_, next_request_++};
  copy3(req.min, min);
  copy3(req.max, max);
  req.max_centers = max_centers;
  BoxQueryAnswer answer;
  auto ok = ask<densemap_msgs_BboxQueryReply>(
      dds_->bq_w, dds_->br_r, dds_->br_ws, req, "box queries",
      [&](const densemap_msgs_BboxQueryReply& r, std::string& /*error*/) {
        answer.map_version = r.map_version;
        answer.occupied = r.occupied;
        answer.free = r.free_cells;
        answer.unknown = r.unknown;
        for (std::uint32_t i = 0; i + 2 < r.occupied_centers._length; i += 3) {
          const float* c = r.occupied_centers._buffer + i;
          answer.occupied_centers.emplace_back(c[0], c[1], c[2]);
        }
      });
  if (!ok) return std::unexpected(ok.error());
  return answer;
}

Expected<RayQueryAnswer> Client::Impl::castRay(const Point3f& origin, const Point3f& direction,
                                               float max_range) {
  densemap_msgs_RayQueryRequest req{};
  req.id = {client_id_, next_request_++};
  copy3(req.origin, origin);
  copy3(req.direction, direction);
  req.max_range = max_range;
  RayQueryAnswer answer;
  auto ok = ask<densemap_msgs_RayQueryReply>(
      dds_->rq_w, dds_->rr_r, dds_->rr_ws, req, "ray queries",
      [&](const densemap_msgs_RayQueryReply& r, std::string& /*error*/) {
        answer.map_version = r.map_version;
        answer.ray.hit = r.hit;
        answer.ray.hit_center = Point3f(r.hit_point[0], r.hit_point[1], r.hit_point[2]);
        answer.ray.distance = r.distance;
      });
  if (!ok) return std::unexpected(ok.error());
  return answer;
}

Expected<DistanceQueryAnswer> Client::Impl::queryDistancesOnce(
    std::span<const float> xyz, const DistanceQueryOptions& options) {
  densemap_msgs_DistanceQueryRequest req{};
  req.id = {client_id_, next_request_++};
  req.points = dds::borrowSequence<dds_sequence_float>(xyz);
  req.unknown_as_occupied = options.unknown_as_occupied;
  req.interpolate = options.interpolate;
  req.nearest = options.nearest;
  DistanceQueryAnswer answer;
  auto ok = ask<densemap_msgs_DistanceQueryReply>(
      dds_->dq_w, dds_->dr_r, dds_->dr_ws, req, "distance queries",
      [&](const densemap_msgs_DistanceQueryReply& r, std::string& error) {
        const std::size_t n = xyz.size() / 3;
        if (r.distances._length != n || r.gradients._length != 3 * n ||
            r.nearest._length != 3 * n) {
          error =
              "a reply whose lengths do not match the request's " + std::to_string(n) + " points";
          return;
        }
        answer.map_version = r.map_version;
        answer.max_distance = r.max_distance;
        answer.distances.assign(r.distances._buffer, r.distances._buffer + n);
        answer.gradients.assign(r.gradients._buffer, r.gradients._buffer + 3 * n);
        answer.nearest.assign(r.nearest._buffer, r.nearest._buffer + 3 * n);
      });
  if (!ok) return std::unexpected(ok.error());
  return answer;
}

namespace {

/// A swept-volume conflict from the wire (paths and boxes alike).
SweptConflict conflictOf(const densemap_msgs_PathConflict& c) {
  SweptConflict out;
  out.center = Point3f(c.center[0], c.center[1], c.center[2]);
  out.arc_length = c.arc_length;
  out.index = c.segment;
  return out;
}

}  // namespace

Expected<PathQueryAnswer> Client::Impl::checkPath(std::span<const float> xyz, double radius) {
  if (xyz.size() % 3 != 0) return makeError("path length is not a multiple of 3 (x y z each)");
  if (xyz.size() / 3 > dds::kMaxPathVertices) {
    return makeError("path of " + std::to_string(xyz.size() / 3) + " vertices, more than the " +
                     std::to_string(dds::kMaxPathVertices) + " one request may carry");
  }
  densemap_msgs_PathQueryRequest req{};
  req.id = {client_id_, next_request_++};
  req.vertices = dds::borrowSequence<dds_sequence_float>(xyz);
  req.radius = radius;
  PathQueryAnswer answer;
  auto ok = ask<densemap_msgs_PathQueryReply>(
      dds_->paq_w, dds_->par_r, dds_->par_ws, req, "path queries",
      [&](const densemap_msgs_PathQueryReply& r, std::string& /*error*/) {
        answer.map_version = r.map_version;
        answer.state = r.state <= 2 ? static_cast<CellState>(r.state) : CellState::kUnknown;
        if (r.has_occupied) answer.occupied = conflictOf(r.occupied);
        if (r.has_unknown) answer.unknown = conflictOf(r.unknown);
        answer.length_m = r.length;
      });
  if (!ok) return std::unexpected(ok.error());
  return answer;
}

Expected<PathQueryAnswer> Client::Impl::checkBoxes(std::span<const OrientedBox> boxes) {
  if (boxes.empty() || boxes.size() > dds::kMaxQueryBoxes) {
    return makeError("1 to " + std::to_string(dds::kMaxQueryBoxes) + " boxes in one request, got " +
                     std::to_string(boxes.size()));
  }
  std::vector<float> floats;
  floats.reserve(boxes.size() * kBoxFloats);
  for (const OrientedBox& b : boxes) appendBoxFloats(b, floats);
  densemap_msgs_BoxesQueryRequest req{};
  req.id = {client_id_, next_request_++};
  req.boxes = dds::borrowSequence<dds_sequence_float>(floats);
  PathQueryAnswer answer;
  auto ok = ask<densemap_msgs_BoxesQueryReply>(
      dds_->oq_w, dds_->or_r, dds_->or_ws, req, "oriented-box queries",
      [&](const densemap_msgs_BoxesQueryReply& r, std::string& /*error*/) {
        answer.map_version = r.map_version;
        answer.state = r.state <= 2 ? static_cast<CellState>(r.state) : CellState::kUnknown;
        if (r.has_occupied) answer.occupied = conflictOf(r.occupied);
        if (r.has_unknown) answer.unknown = conflictOf(r.unknown);
      });
  if (!ok) return std::unexpected(ok.error());
  return answer;
}

Expected<DistanceBoxAnswer> Client::Impl::distanceBox(const Point3f& min, const Point3f& max,
                                                      bool unknown_as_occupied) {
  densemap_msgs_DistanceBoxRequest req{};
  req.id = {client_id_, next_request_++};
  for (int i = 0; i < 3; ++i) {
    req.min[i] = min[i];
    req.max[i] = max[i];
  }
  req.unknown_as_occupied = unknown_as_occupied;
  DistanceBoxAnswer answer;
  auto ok = ask<densemap_msgs_DistanceBoxReply>(
      dds_->dbq_w, dds_->dbr_r, dds_->dbr_ws, req, "distance boxes",
      [&](const densemap_msgs_DistanceBoxReply& r, std::string& error) {
        const std::uint64_t cells =
            std::uint64_t{r.size[0]} * std::uint64_t{r.size[1]} * std::uint64_t{r.size[2]};
        if (cells != r.distances._length) {
          error = "a distance box of " + std::to_string(r.distances._length) + " values for " +
                  std::to_string(cells) + " cells";
          return;
        }
        answer.map_version = r.map_version;
        answer.max_distance = r.max_distance;
        answer.min_center = Point3f(r.min_center[0], r.min_center[1], r.min_center[2]);
        answer.size = {r.size[0], r.size[1], r.size[2]};
        answer.distances.assign(r.distances._buffer, r.distances._buffer + r.distances._length);
      });
  if (!ok) return std::unexpected(ok.error());
  return answer;
}

Expected<std::string> Client::Impl::command(dds::CommandKind kind, const Point3f& min,
                                            const Point3f& max, const std::string& path) {
  auto outcome = commandReply(kind, min, max, path);
  if (!outcome) return std::unexpected(outcome.error());
  return outcome->detail;
}

Expected<Client::Impl::CommandOutcome> Client::Impl::commandReply(dds::CommandKind kind,
                                                                  const Point3f& min,
                                                                  const Point3f& max,
                                                                  const std::string& path) {
  densemap_msgs_CommandRequest req{};
  req.id = {client_id_, next_request_++};
  req.kind = static_cast<std::int32_t>(kind);
  copy3(req.min, min);
  copy3(req.max, max);
  req.path = const_cast<char*>(path.c_str());
  // send-map has a topic of its own (DDS Security can grant it without the others).
  const dds::Entity& writer = kind == dds::CommandKind::kSendMap ? dds_->mq_w : dds_->cq_w;
  if (auto ok = permitted(writer, "this command"); !ok) return std::unexpected(ok.error());
  if (auto ok = permitted(dds_->cr_r, "command replies"); !ok) return std::unexpected(ok.error());
  if (auto ok = dds::write(writer, &req); !ok) return std::unexpected(ok.error());
  CommandOutcome outcome;
  std::string error;
  // Commands wait for the scan in flight and may write large files: allow more time.
  auto ok = awaitReply<densemap_msgs_CommandReply>(
      dds_->cr_r, *dds_->cr_ws, req.id, options_.timeout * 6,
      [&](const densemap_msgs_CommandReply& r) {
        if (r.status != 0) error = text(r.error);
        outcome = {text(r.detail), r.sent_version, r.sent_tiles, r.sent_cells, {}};
        if (r.sent_stamps._length > dds::kMaxSentStamps) {
          error = "a reply naming " + std::to_string(r.sent_stamps._length) + " sensors (at most " +
                  std::to_string(dds::kMaxSentStamps) + ")";
          return;
        }
        for (std::uint32_t i = 0; i < r.sent_stamps._length; ++i) {
          outcome.sent_stamps.emplace_back(text(r.sent_stamps._buffer[i].sensor_id),
                                           r.sent_stamps._buffer[i].stamp_ns);
        }
      });
  if (!ok) return std::unexpected(ok.error());
  if (!error.empty()) return makeError("server: " + error);
  return outcome;
}

Expected<ServerStatus> Client::Impl::status() {
  if (auto ok = permitted(dds_->st_r, "status"); !ok) return std::unexpected(ok.error());
  const auto deadline = Clock::now() + options_.timeout;
  std::optional<ServerStatus> latest;
  while (true) {
    // read, not take: the transient-local sample stays for the next call.
    void* samples[1] = {nullptr};
    dds_sample_info_t info[1];
    const dds_return_t n = dds_read(dds_->st_r.get(), samples, info, 1, 1);
    // The last status stays readable after its server stops: a gone writer is an error, not a
    // status (`densemap status --watch` repeated the last one forever).
    if (n > 0 && info[0].instance_state != DDS_IST_ALIVE) {
      (void)dds_return_loan(dds_->st_r.get(), samples, n);
      return makeError("the densemap-server on DDS domain " + std::to_string(options_.domain_id) +
                       " has stopped (its status is gone)");
    }
    if (n > 0 && info[0].valid_data) {
      latest = dds::statusFromWire(*static_cast<const densemap_msgs_Status*>(samples[0]));
    }
    if (n > 0) dds_return_loan(dds_->st_r.get(), samples, n);
    if (latest) return *latest;
    if (Clock::now() > deadline) return makeError("no status from densemap-server");
    std::this_thread::sleep_for(std::chrono::milliseconds(20));
  }
}

Expected<void> Client::waitForServer() { return impl_->waitForServer(); }
Expected<void> Client::publishScan(const RawScan& scan) { return impl_->publishScan(scan); }

Expected<void> Client::publishPoseCorrection(const PoseCorrection& correction) {
  return impl_->publishPoseCorrection(correction);
}
Expected<BoxQueryAnswer> Client::queryBox(const Point3f& min, const Point3f& max,
                                          std::uint32_t max_centers) {
  return failingOver([&](Impl& i) { return i.queryBox(min, max, max_centers); });
}
Expected<DistanceQueryAnswer> Client::queryDistances(std::span<const float> xyz_world,
                                                     const DistanceQueryOptions& options) {
  if (auto ok = checkPointCoordinates(xyz_world.size()); !ok) return std::unexpected(ok.error());
  // Parts of at most kMaxQueryPoints points, one after another, as queryPoints sends them.
  constexpr std::size_t kPart = std::size_t{dds::kMaxQueryPoints} * 3;
  DistanceQueryAnswer answer;
  for (std::size_t from = 0; from < xyz_world.size() || from == 0; from += kPart) {
    const std::size_t n = std::min(kPart, xyz_world.size() - from);
    auto part = failingOver(
        [&](Impl& i) { return i.queryDistancesOnce(xyz_world.subspan(from, n), options); });
    if (!part) return std::unexpected(part.error());
    answer.map_version = part->map_version;
    answer.max_distance = part->max_distance;
    answer.distances.insert(answer.distances.end(), part->distances.begin(), part->distances.end());
    answer.gradients.insert(answer.gradients.end(), part->gradients.begin(), part->gradients.end());
    answer.nearest.insert(answer.nearest.end(), part->nearest.begin(), part->nearest.end());
    if (n != kPart) break;
  }
  return answer;
}

Expected<PathQueryAnswer> Client::checkBoxes(std::span<const OrientedBox> boxes) {
  return failingOver([&](Impl& i) { return i.checkBoxes(boxes); });
}

Expected<DistanceBoxAnswer> Client::distanceBox(const Point3f& min, const Point3f& max,
                                                bool unknown_as_occupied) {
  return failingOver([&](Impl& i) { return i.distanceBox(min, max, unknown_as_occupied); });
}

Expected<PathQueryAnswer> Client::checkPath(std::span<const float> vertices_world,
                                            double radius_m) {
  return failingOver([&](Impl& i) { return i.checkPath(vertices_world, radius_m); });
}

Expected<RayQueryAnswer> Client::castRay(const Point3f& origin, const Point3f& direction,
                                         float max_range) {
  return failingOver([&](Impl& i) { return i.castRay(origin, direction, max_range); });
}
Expected<std::string> Client::reset() {
  return impl_->command(dds::CommandKind::kReset, {0, 0, 0}, {0, 0, 0}, {});
}
Expected<std::string> Client::clearBox(const Point3f& min, const Point3f& max) {
  return impl_->command(dds::CommandKind::kClearBox, min, max, {});
}
Expected<std::string> Client::save(const std::string& name) {
  return impl_->command(dds::CommandKind::kSave, {0, 0, 0}, {0, 0, 0}, name);
}
Expected<ServerStatus> Client::status() { return impl_->status(); }
std::size_t Client::pollDeltas(const std::function<void(const DeltaInfo&)>& f) {
  return impl_->pollDeltas(f);
}
std::size_t Client::pollEvents(const std::function<void(const MapEventInfo&)>& f) {
  return impl_->pollEvents(f);
}
Expected<MapManifestInfo> Client::manifest() { return impl_->manifest(); }
Expected<MapSnapshot> Client::fetchMap(std::uint64_t min_version) {
  return impl_->fetchMap(min_version);
}

namespace testing {

Expected<PointQueryAnswer> queryPointsRaw(Client& client, const std::vector<float>& xyz) {
  return ClientAccess::impl(client).queryPointsRaw(xyz);
}

Expected<PointQueryAnswer> queryPointsOnce(Client& client, std::span<const float> xyz) {
  return ClientAccess::impl(client).queryPointsOnce(xyz);
}

const GridMap& gridOf(const MapSnapshot& snapshot) { return MapSnapshotAccess::grid(snapshot); }

}  // namespace testing
}  // namespace densemap
