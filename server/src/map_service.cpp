#include "densemap/server/map_service.hpp"

#include "densemap/server/export_path.hpp"

#include <spdlog/spdlog.h>

#include <malloc.h>
#include <tbb/blocked_range.h>
#include <tbb/parallel_for.h>

#include <algorithm>
#include <bit>
#include <cmath>
#include <limits>
#include <thread>
#include <tuple>
#include <unordered_map>
#include <vector>

#include "densemap/dds/delta_wire.hpp"
#include "densemap/dds/topics.hpp"
#include "densemap/io/process_usage.hpp"
#include "densemap/query/map_queries.hpp"
#include "densemap/query/version_delta.hpp"
#include "densemap/store/snapshot.hpp"
#include "densemap_msgs.h"

namespace densemap::server {

namespace {

constexpr std::int32_t kOk = 0, kInvalid = 1, kInternal = 2;

// Attachment tags of the service waitset.
constexpr dds_attach_t kPointTag = 1, kBboxTag = 2, kRayTag = 3, kCmdTag = 4, kScanTag = 5,
                       kMapTag = 6;

Point3f toPoint(const float (&v)[3]) { return {v[0], v[1], v[2]}; }

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

// Beyond this many queries waiting for a task, requests stay in the DDS readers (keep-last).
constexpr int kMaxQueriesInFlight = 64;
// Once this many request bytes were served and none is in flight, the status tick hands the
// heap's free memory back to the OS.
constexpr std::size_t kTrimAfterBytes = std::size_t{16} << 20;
// How long a reply waits for its writer to match the asker's reply reader (discovery of a new
// client usually completes within milliseconds on loopback).
constexpr std::chrono::milliseconds kAskerWait{2000};
// Participants tracked for the asker wait (beyond it, entries past their wait are dropped).
constexpr std::size_t kMaxAskersTracked = 4096;
// Reply writers kept (one per client and reply topic; the least recently used beyond go).
constexpr std::size_t kMaxReplyWriters = 1024;
// Beyond this many versions waiting for the publish thread, their deltas are coalesced.
constexpr std::size_t kMaxPendingVersions = 8;

}  // namespace

struct MapService::Dds {
  dds::Entity participant;
  dds::Topics topics;
  dds::Entity scan_reader, point_reader, bbox_reader, ray_reader, cmd_reader, map_reader;
  // Replies go out through writers made per asking client (MapService::replyWriter).
  dds::Entity manifest_writer, tile_writer, delta_writer, event_writer, status_writer;
  std::optional<dds::WaitSet> ingest_waitset;
  std::optional<dds::WaitSet> service_waitset;
  dds::Entity status_probe;  // reads densemap/status: matches every server's status writer
};

Expected<std::unique_ptr<MapService>> MapService::create(Pipeline& pipeline,
                                                         const ServiceOptions& options) {
  std::unique_ptr<MapService> service(new MapService(pipeline, options));
  auto& d = *service->dds_;
  auto participant =
      dds::createParticipant({options.domain_id, options.network_interface, options.security});
  if (!participant) return std::unexpected(participant.error());
  d.participant = std::move(*participant);
  Expected<void> status;
  auto topics = dds::Topics::create(d.participant);
  if (!topics) return std::unexpected(topics.error());
  d.topics = std::move(*topics);
  auto reader = [&](dds::Entity& out, const dds::Entity& t, dds::QosSpec q) {
    if (!status) return;
    auto r = dds::createReader(d.participant, t, q);
    if (!r)
      status = std::unexpected(r.error());
    else
      out = std::move(*r);
  };
  auto writer = [&](dds::Entity& out, const dds::Entity& t, dds::QosSpec q) {
    if (!status) return;
    auto w = dds::createWriter(d.participant, t, q);
    if (!w)
      status = std::unexpected(w.error());
    else
      out = std::move(*w);
  };
  // Another server on the domain? Checked before any endpoint a client or robot would match
  // (scans and requests sent meanwhile would wait unread in this server's readers).
  reader(d.status_probe, d.topics.status, dds::kLatestStateQos);
  if (!status) return std::unexpected(status.error());
  if (auto alone = service->checkAlone(options.alone_discovery); !alone) {
    return std::unexpected(alone.error());
  }
  const dds::QosSpec requests = dds::kRequestQos;
  reader(d.scan_reader, d.topics.scan, {.depth = 4});
  reader(d.point_reader, d.topics.point_request, requests);
  reader(d.bbox_reader, d.topics.bbox_request, requests);
  reader(d.ray_reader, d.topics.ray_request, requests);
  reader(d.cmd_reader, d.topics.command_request, dds::kCommandQos);
  reader(d.map_reader, d.topics.map_request, dds::kCommandQos);
  writer(d.manifest_writer, d.topics.manifest, dds::kLatestStateQos);
  writer(d.tile_writer, d.topics.tiles, dds::kTileQos);
  writer(d.delta_writer, d.topics.delta, {.depth = 32});
  writer(d.event_writer, d.topics.events, {.depth = 64});
  writer(d.status_writer, d.topics.status, dds::kLatestStateQos);
  if (!status) return std::unexpected(status.error());

  auto ingest_ws = dds::WaitSet::create(d.participant);
  auto service_ws = dds::WaitSet::create(d.participant);
  if (!ingest_ws || !service_ws) return makeError("cannot create DDS waitsets");
  d.ingest_waitset.emplace(std::move(*ingest_ws));
  d.service_waitset.emplace(std::move(*service_ws));
  for (auto [r, tag] : {std::pair{&d.point_reader, kPointTag}, std::pair{&d.bbox_reader, kBboxTag},
                        std::pair{&d.ray_reader, kRayTag}, std::pair{&d.cmd_reader, kCmdTag},
                        std::pair{&d.map_reader, kMapTag}}) {
    if (auto ok = d.service_waitset->attachReader(*r, tag); !ok) return std::unexpected(ok.error());
  }
  if (auto ok = d.ingest_waitset->attachReader(d.scan_reader, kScanTag); !ok) {
    return std::unexpected(ok.error());
  }
  if (options.ros2) {
    auto bridge = Ros2Bridge::create(pipeline, d.participant, *options.ros2);
    if (!bridge) return std::unexpected(bridge.error());
    service->ros2_ = std::move(*bridge);
  }
  pipeline.setPublisher(
      [s = service.get()](const IntegrationResult& r, const std::shared_ptr<const MapView>& v) {
        s->onIntegrated(r, v);
      });
  // The map loaded from a snapshot is published as tiles right away.
  service->delta_base_ = pipeline.view();
  return service;
}

std::vector<std::string> MapService::otherServers() const {
  dds_guid_t own{};
  (void)dds_get_guid(dds_->participant.get(), &own);
  std::vector<dds_instance_handle_t> handles(16);
  dds_return_t n =
      dds_get_matched_publications(dds_->status_probe.get(), handles.data(), handles.size());
  if (n > static_cast<dds_return_t>(handles.size())) {
    handles.resize(static_cast<std::size_t>(n));
    n = dds_get_matched_publications(dds_->status_probe.get(), handles.data(), handles.size());
  }
  std::vector<std::string> others;
  for (dds_return_t i = 0; i < std::min<dds_return_t>(n, handles.size()); ++i) {
    dds_builtintopic_endpoint_t* e =
        dds_get_matched_publication_data(dds_->status_probe.get(), handles[i]);
    if (e == nullptr) continue;
    const bool mine = std::equal(std::begin(e->participant_key.v), std::end(e->participant_key.v),
                                 std::begin(own.v));
    if (!mine) {
      char guid[40];
      const auto& v = e->participant_key.v;
      std::snprintf(guid, sizeof guid, "%02x%02x%02x%02x:%02x%02x%02x%02x:%02x%02x%02x%02x", v[0],
                    v[1], v[2], v[3], v[4], v[5], v[6], v[7], v[8], v[9], v[10], v[11]);
      others.emplace_back(guid);
    }
    dds_builtintopic_free_endpoint(e);
  }
  return others;
}

Expected<void> MapService::checkAlone(std::chrono::milliseconds discovery) const {
  const auto deadline = std::chrono::steady_clock::now() + discovery;
  while (true) {
    if (const auto others = otherServers(); !others.empty()) {
      return makeError(std::string(kAnotherServer) + " (participant " + others.front() +
                       ") already runs on DDS domain " + std::to_string(options_.domain_id) +
                       ": two servers on one domain would answer the same clients with two "
                       "maps; stop it, or give this one another dds.domain_id / --domain-id");
    }
    if (std::chrono::steady_clock::now() >= deadline) return {};
    std::this_thread::sleep_for(std::chrono::milliseconds(20));
  }
}

MapService::MapService(Pipeline& pipeline, const ServiceOptions& options)
    : pipeline_(pipeline),
      options_(options),
      dds_(std::make_unique<Dds>()),
      // No slot kept for a master (the service thread only enqueues); high priority, so free
      // workers take queries before integration's spare work.
      query_arena_(std::max(1, options.query_threads), 0, tbb::task_arena::priority::high) {}

MapService::~MapService() { stop(); }

void MapService::start() {
  if (running_.exchange(true)) return;
  ingest_ = std::thread([this] { ingestLoop(); });
  service_ = std::thread([this] { serviceLoop(); });
  publish_ = std::thread([this] { publishLoop(); });
  if (ros2_) ros2_->start();
}

void MapService::stop() {
  if (!running_.exchange(false)) return;
  if (ros2_) ros2_->stop();  // no more ROS clouds
  dds_->ingest_waitset->wake();
  dds_->service_waitset->wake();
  versions_cv_.notify_all();
  if (ingest_.joinable()) ingest_.join();
  if (service_.joinable()) service_.join();
  query_arena_.execute([this] { queries_.wait(); });
  if (publish_.joinable()) publish_.join();
}

void MapService::ingestLoop() {
  // Only takes and enqueues: validation and integration happen in the pipeline.
  while (running_.load()) {
    dds_->ingest_waitset->wait(std::chrono::milliseconds(200));
    dds::takeAll<densemap_msgs_Scan>(dds_->scan_reader, [&](const densemap_msgs_Scan& msg) {
      RawScan raw;
      raw.sensor_id = msg.sensor_id != nullptr ? msg.sensor_id : "";
      raw.seq = msg.seq;
      raw.stamp_ns = msg.stamp_ns;
      for (int i = 0; i < 3; ++i) raw.t_world_sensor[i] = msg.T_world_sensor.t[i];
      for (int i = 0; i < 4; ++i) raw.q_world_sensor[i] = msg.T_world_sensor.q[i];
      raw.xyz.assign(msg.points._buffer, msg.points._buffer + msg.points._length);
      raw.intensity.assign(msg.intensity._buffer, msg.intensity._buffer + msg.intensity._length);
      pipeline_.submit(std::move(raw));
    });
  }
}

void MapService::serviceLoop() {
  while (running_.load()) {
    dds_->service_waitset->wait(std::chrono::milliseconds(100));
    takeQueries();
    answerCommands();
  }
}

void MapService::publishLoop() {
  auto next_status = std::chrono::steady_clock::now();
  const auto autosave_period = std::chrono::duration_cast<std::chrono::steady_clock::duration>(
      std::chrono::duration<double>(options_.autosave_period_s));
  auto next_save = next_status + autosave_period;
  const bool autosave = options_.autosave_period_s > 0 && !options_.snapshot_path.empty();
  std::uint64_t saved_version = pipeline_.view()->version();  // what the file already holds
  std::deque<Version> versions;
  while (running_.load()) {
    {
      std::unique_lock lock(versions_mutex_);
      versions_cv_.wait_until(lock, autosave ? std::min(next_status, next_save) : next_status,
                              [&] { return !versions_.empty() || !running_.load(); });
      versions.swap(versions_);
    }
    publishDeltas(versions);
    const auto now = std::chrono::steady_clock::now();
    heartbeat_ = now.time_since_epoch().count();
    if (now >= next_status) {
      publishStatus();
      publishManifest();
      next_status = now + std::chrono::seconds(1);
      // Requests served and none in flight: the heap goes back to the OS (RSS stayed ~850 MB
      // after a flood until a save trimmed it). At the status tick, a second or so after the
      // last reply: its serialised copy leaves DDS's writer history once the asker acknowledged
      // it.
      if (request_bytes_.load() == 0 && served_since_trim_.load() > kTrimAfterBytes) {
        served_since_trim_ = 0;
        malloc_trim(0);
      }
    }
    // Autosave only a changed map: a daemon idle for months does not rewrite the same file.
    if (autosave && now >= next_save) {
      const std::uint64_t version = pipeline_.view()->version();
      auto pause = autosave_period;
      if (version != saved_version) {
        const auto began = std::chrono::steady_clock::now();
        if (auto ok = save(); !ok) {
          spdlog::warn("autosave failed: {}", ok.error().message);  // counted by save()
        } else {
          saved_version = version;
        }
        // A short period on a large map would mean back-to-back full rewrites: saving takes
        // at most a fifth of the time.
        pause = std::max(pause, 4 * (std::chrono::steady_clock::now() - began));
      }
      next_save = std::chrono::steady_clock::now() + pause;
    }
  }
  {
    std::lock_guard lock(versions_mutex_);
    versions.swap(versions_);
  }
  publishDeltas(versions);
  publishStatus();
  publishManifest();
}

void MapService::onIntegrated(const IntegrationResult& r,
                              const std::shared_ptr<const MapView>& view) {
  // On the pipeline's worker: a small event now, everything else on the publish thread.
  if (ros2_) ros2_->onVersion(r, view);
  densemap_msgs_MapEvent event{};
  event.base_version = r.base_version;
  event.new_version = r.new_version;
  event.sensor_id = const_cast<char*>(r.sensor_id.c_str());
  event.scan_seq = r.scan_seq;
  event.scan_stamp_ns = r.stamp_ns;
  event.from_scan = r.from_scan;
  event.changed_cells = r.from_scan ? r.stats.changed : r.changes.size();
  event.written_blocks = static_cast<std::uint32_t>(r.written_blocks.size());
  event.latency_ms = r.latency_ms;
  (void)dds::write(dds_->event_writer, &event);
  Version v;
  v.result.from_scan = r.from_scan;
  v.result.sensor_id = r.sensor_id;
  v.result.scan_seq = r.scan_seq;
  v.result.stamp_ns = r.stamp_ns;
  v.result.base_version = r.base_version;
  v.result.new_version = r.new_version;
  v.result.written_blocks = r.written_blocks;
  v.view = view;
  {
    std::lock_guard lock(versions_mutex_);
    versions_.push_back(std::move(v));
  }
  versions_cv_.notify_one();
}

void MapService::publishDeltas(std::deque<Version>& versions) {
  if (versions.empty()) return;
  dds_publication_matched_status_t matched{};
  const bool wanted = dds_get_publication_matched_status(dds_->delta_writer.get(), &matched) >= 0 &&
                      matched.current_count > 0;
  if (!wanted) {  // nobody listens: no delta is built
    delta_base_ = versions.back().view;
    versions.clear();
    return;
  }
  // A backlog goes out as one delta from the last base to the newest version.
  if (versions.size() > kMaxPendingVersions) {
    Version merged = std::move(versions.back());
    for (std::size_t i = 0; i + 1 < versions.size(); ++i) {
      auto& blocks = versions[i].result.written_blocks;
      merged.result.written_blocks.insert(merged.result.written_blocks.end(), blocks.begin(),
                                          blocks.end());
    }
    versions.clear();
    versions.push_back(std::move(merged));
  }
  for (Version& v : versions) {
    VersionDelta delta = diffVersions(*delta_base_, *v.view, v.result.written_blocks);
    densemap_msgs_MapDelta msg{};
    msg.base_version = delta_base_->version();
    msg.new_version = v.view->version();
    msg.sensor_id = const_cast<char*>(v.result.sensor_id.c_str());
    msg.scan_seq = v.result.scan_seq;
    msg.scan_stamp_ns = v.result.stamp_ns;
    msg.from_scan = v.result.from_scan;
    dds::borrowCells(msg, delta);
    (void)dds::write(dds_->delta_writer, &msg);
    delta_base_ = v.view;
  }
  versions.clear();
}

void MapService::noteBadRequest(const std::string& error) {
  spdlog::debug("refused request: {}", error);
  ++queries_rejected_;
  std::lock_guard lock(error_mutex_);
  last_query_error_ = error;
}

namespace {

void answerPoints(const dds::Entity& writer, const PointRequest& req, const MapView& view,
                  std::string& error) {
  densemap_msgs_PointQueryReply rep{};
  rep.id = req.id;
  rep.map_version = view.version();
  auto result = queryPoints(view, req.xyz);
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

}  // namespace

namespace {

/// After work that allocates and frees a copy of the map (a snapshot, a late joiner's tiles):
/// hands the freed memory back to the system. glibc keeps freed memory in per-thread arenas,
/// so without this a daemon's RSS climbs to the sum of each thread's peak (seen as +10% steps
/// in a 2-minute soak).
struct ReturnFreeMemory {
  ReturnFreeMemory() = default;
  ReturnFreeMemory(const ReturnFreeMemory&) = delete;
  ReturnFreeMemory& operator=(const ReturnFreeMemory&) = delete;
  ~ReturnFreeMemory() { malloc_trim(0); }
};

}  // namespace

void MapService::runTask(std::function<void()> task, std::size_t bytes) {
  ++queries_in_flight_;
  request_bytes_ += bytes;
  query_arena_.execute([&] {
    queries_.run([this, bytes, task = std::move(task)] {
      task();
      request_bytes_ -= bytes;
      served_since_trim_ += bytes;
      --queries_in_flight_;
    });
  });
}

std::size_t MapService::pointRequestBytes(std::size_t coordinates) {
  // The request's copy (12 bytes a point), the reply's values and states (5 bytes a point) and
  // the DDS sample written (about as much again).
  return coordinates * sizeof(float) + coordinates / 3 * 2 * (sizeof(float) + 1);
}

void MapService::takeQueries() {
  // Each request becomes a task answered from the latest version when it runs; the task reads
  // one view throughout, so a multi-cell answer is one consistent version.
  auto spawn = [this](auto answer, std::size_t bytes = 0) {
    runTask(
        [this, answer = std::move(answer)] {
          std::string error;
          answer(*pipeline_.view(), error);
          if (!error.empty()) noteBadRequest(error);
          ++queries_answered_;
        },
        bytes);
  };
  // Take one request at a time from each reader in turn, so no kind starves the others. Each
  // reply waits (at most kAskerWait) until its writer has matched the asker's reply reader:
  // discovery is not symmetric, and a reply written before that match is lost (issue 28,
  // item 4: 1-3% of one-shot queries timed out while the server had answered).
  const auto asker = [](const dds::Entity& reader, const dds_sample_info_t& info) {
    return dds::participantOfWriter(reader, info.publication_handle);
  };
  // Requests in flight share one memory budget (pipeline.request_budget_mb): while it is spent,
  // new requests wait in DDS (bounded by the readers' depth); one that could never fit is refused.
  bool took = true;
  while (took && queries_in_flight_.load() < kMaxQueriesInFlight &&
         request_bytes_.load() < options_.request_budget_bytes) {
    took = dds::takeOneWithInfo<densemap_msgs_PointQueryRequest>(
        dds_->point_reader,
        [&](const densemap_msgs_PointQueryRequest& m, const dds_sample_info_t& info) {
          const std::size_t bytes = pointRequestBytes(m.points._length);
          std::string refusal;
          if (m.points._length / 3 > dds::kMaxQueryPoints) {
            refusal = std::to_string(m.points._length / 3) +
                      " query points in one request: at most " +
                      std::to_string(dds::kMaxQueryPoints) +
                      " (densemap's client library splits larger batches)";
          } else if (bytes > options_.request_budget_bytes) {
            refusal = std::to_string(m.points._length / 3) + " query points need " +
                      std::to_string(bytes >> 20) + " MiB, over the server's request budget of " +
                      std::to_string(options_.request_budget_bytes >> 20) +
                      " MiB (pipeline.request_budget_mb): send smaller batches";
          }
          if (!refusal.empty()) {
            densemap_msgs_PointQueryReply rep{};
            rep.id = m.id;
            rep.status = kInvalid;
            rep.error = const_cast<char*>(refusal.c_str());
            if (const auto w = replyWriter(ReplyTopic::kPoint, m.id.client_id)) {
              awaitAsker(*w, asker(dds_->point_reader, info));
              (void)dds::write(*w, &rep);
            }
            noteBadRequest(refusal);
            return;
          }
          PointRequest req{
              m.id, std::vector<float>(m.points._buffer, m.points._buffer + m.points._length)};
          const auto w = replyWriter(ReplyTopic::kPoint, m.id.client_id);
          if (!w) return;
          spawn(
              [this, w, req = std::move(req), who = asker(dds_->point_reader, info)](
                  const MapView& view, std::string& error) {
                awaitAsker(*w, who);
                answerPoints(*w, req, view, error);
              },
              bytes);
        });
    took |= dds::takeOneWithInfo<densemap_msgs_BboxQueryRequest>(
        dds_->bbox_reader,
        [&](const densemap_msgs_BboxQueryRequest& m, const dds_sample_info_t& info) {
          BboxRequest req{m.id, toPoint(m.min), toPoint(m.max), m.max_centers};
          const auto w = replyWriter(ReplyTopic::kBbox, m.id.client_id);
          if (!w) return;
          spawn([this, w, req, who = asker(dds_->bbox_reader, info)](const MapView& view,
                                                                     std::string& error) {
            awaitAsker(*w, who);
            answerBox(*w, req, view, options_.max_query_cells, error);
          });
        });
    took |= dds::takeOneWithInfo<densemap_msgs_RayQueryRequest>(
        dds_->ray_reader,
        [&](const densemap_msgs_RayQueryRequest& m, const dds_sample_info_t& info) {
          RayRequest req{m.id, toPoint(m.origin), toPoint(m.direction), m.max_range};
          const auto w = replyWriter(ReplyTopic::kRay, m.id.client_id);
          if (!w) return;
          spawn([this, w, req, who = asker(dds_->ray_reader, info)](const MapView& view,
                                                                    std::string& error) {
            awaitAsker(*w, who);
            answerRay(*w, req, view, error);
          });
        });
  }
}

void MapService::awaitAsker(const dds::Entity& writer, const std::optional<dds_guid_t>& asker) {
  if (!asker) return;
  const std::string who(reinterpret_cast<const char*>(asker->v), sizeof asker->v);
  const std::string pair = std::to_string(writer.get()) + ":" + who;
  std::chrono::steady_clock::duration left{};
  {
    // Seen matched before: no lookup (the matched list is O(clients) per reply). Else the wait
    // is what is left of kAskerWait since this participant's first request, so a participant
    // that never creates a reply reader holds a query thread once, not once per request.
    std::lock_guard lock(askers_mutex_);
    if (askers_matched_.contains(pair)) return;
    const auto now = std::chrono::steady_clock::now();
    if (asker_first_seen_.size() > kMaxAskersTracked) {
      std::erase_if(asker_first_seen_, [&](const auto& e) { return now - e.second > kAskerWait; });
    }
    const auto first = asker_first_seen_.try_emplace(who, now).first->second;
    left = std::max(std::chrono::steady_clock::duration::zero(), kAskerWait - (now - first));
  }
  if (!dds::waitForReaderOf(writer, *asker,
                            std::chrono::duration_cast<std::chrono::milliseconds>(left))) {
    spdlog::debug("a reply goes out before its asker's reader matched");
    return;
  }
  std::lock_guard lock(askers_mutex_);
  if (askers_matched_.size() > kMaxAskersTracked) askers_matched_.clear();  // a cache only
  askers_matched_.insert(pair);
}

void MapService::answerCommands() {
  // send-map: a task, so it does not hold up other commands.
  const auto send_map = [this](const densemap_msgs_RequestId& id) {
    runTask([this, id] {
      const Expected<SentMap> sent = sendMap(id);
      if (!sent) {
        replyCommand(id, std::unexpected(sent.error()));
        return;
      }
      replyCommand(id,
                   "version " + std::to_string(sent->version) + ": " +
                       std::to_string(sent->tiles) + " tiles, " + std::to_string(sent->cells) +
                       " cells",
                   *sent);
    });
  };
  while (dds::takeOneWithInfo<densemap_msgs_CommandRequest>(
      dds_->map_reader,
      [&](const densemap_msgs_CommandRequest& req, const dds_sample_info_t& info) {
        if (const auto w = replyWriter(ReplyTopic::kCommand, req.id.client_id)) {
          awaitAsker(*w, dds::participantOfWriter(dds_->map_reader, info.publication_handle));
        }
        if (static_cast<dds::CommandKind>(req.kind) == dds::CommandKind::kSendMap) {
          send_map(req.id);
        } else {
          replyCommand(req.id,
                       makeError("densemap/map/request takes send-map only; command " +
                                 std::to_string(req.kind) + " goes to densemap/cmd/request"));
        }
      })) {
  }
  while (dds::takeOneWithInfo<densemap_msgs_CommandRequest>(
      dds_->cmd_reader,
      [&](const densemap_msgs_CommandRequest& req, const dds_sample_info_t& info) {
        if (const auto w = replyWriter(ReplyTopic::kCommand, req.id.client_id)) {
          awaitAsker(*w, dds::participantOfWriter(dds_->cmd_reader, info.publication_handle));
        }
        const auto kind = static_cast<dds::CommandKind>(req.kind);
        if (kind == dds::CommandKind::kSendMap) {
          send_map(req.id);
          return;
        }
        Expected<std::string> outcome =
            makeError("unknown command kind " + std::to_string(req.kind));
        const VoxelGrid& grid = pipeline_.view()->grid();
        if (kind == dds::CommandKind::kReset || kind == dds::CommandKind::kClearBox) {
          VoxelKey lo{0, 0, 0}, hi{65535, 65535, 65535};
          bool valid = true;
          if (kind == dds::CommandKind::kClearBox) {
            const auto keys = boxKeys(grid, toPoint(req.min), toPoint(req.max));
            if (!keys) {
              outcome = makeError("clear-bbox: " + keys.error().message);
              valid = false;
            } else {
              std::tie(lo, hi) = *keys;
            }
          }
          if (valid) {
            auto future = pipeline_.command(
                [lo, hi](OccupancyMap& map, CellChanges& changes) -> Expected<std::string> {
                  return "erased " + std::to_string(map.clearBox(lo, hi, &changes)) + " cells";
                });
            outcome = future.get();
          }
        } else if (kind == dds::CommandKind::kSave) {
          // A named file goes into the configured export directory, never where the request
          // says: a client must not overwrite what the server's user may write.
          const std::string name = req.path != nullptr ? req.path : "";
          Expected<std::filesystem::path> target = std::filesystem::path();
          if (!name.empty()) {
            target = confineExportPath(exportDirectory(options_.export_dir, options_.snapshot_path),
                                       name);
          }
          auto saved =
              target ? save(*target) : Expected<std::size_t>(std::unexpected(target.error()));
          if (saved)
            outcome = "saved " + std::to_string(*saved) + " bytes" +
                      (name.empty() ? "" : " to " + target->string());
          else
            outcome = std::unexpected(saved.error());
        }
        replyCommand(req.id, outcome);
      })) {
  }
}

void MapService::replyCommand(const densemap_msgs_RequestId& id,
                              const Expected<std::string>& outcome, const SentMap& sent) {
  densemap_msgs_CommandReply rep{};
  rep.id = id;
  rep.map_version = pipeline_.view()->version();
  rep.sent_version = sent.version;
  rep.sent_tiles = sent.tiles;
  rep.sent_cells = sent.cells;
  const std::string error = outcome ? "" : outcome.error().message;
  const std::string detail = outcome ? *outcome : "";
  if (!outcome) noteBadRequest(error);
  rep.status = outcome ? kOk : kInvalid;
  rep.error = const_cast<char*>(error.c_str());
  rep.detail = const_cast<char*>(detail.c_str());
  if (const auto w = replyWriter(ReplyTopic::kCommand, id.client_id)) (void)dds::write(*w, &rep);
}

std::shared_ptr<const dds::Entity> MapService::replyWriter(ReplyTopic topic,
                                                           std::uint64_t client_id) {
  std::lock_guard lock(reply_writers_mutex_);
  const auto key = std::pair(client_id, static_cast<int>(topic));
  if (auto it = reply_writers_.find(key); it != reply_writers_.end()) {
    it->second.last_used = ++reply_writer_uses_;
    return it->second.writer;
  }
  if (reply_writers_.size() >= kMaxReplyWriters) {  // the least recently used goes
    auto oldest = reply_writers_.begin();
    for (auto it = reply_writers_.begin(); it != reply_writers_.end(); ++it) {
      if (it->second.last_used < oldest->second.last_used) oldest = it;
    }
    reply_writers_.erase(oldest);
  }
  const std::string partition = dds::replyPartition(client_id);
  dds::QosSpec qos = topic == ReplyTopic::kCommand ? dds::kCommandQos : dds::kRequestQos;
  qos.partition = partition;
  const dds::Entity& reply_topic = topic == ReplyTopic::kPoint  ? dds_->topics.point_reply
                                   : topic == ReplyTopic::kBbox ? dds_->topics.bbox_reply
                                   : topic == ReplyTopic::kRay  ? dds_->topics.ray_reply
                                                                : dds_->topics.command_reply;
  auto w = dds::createWriter(dds_->participant, reply_topic, qos);
  if (!w) {
    // The request goes unanswered (its client times out): said in the log.
    spdlog::warn("no reply writer for client {:016x}: {}", client_id, w.error().message);
    return nullptr;
  }
  auto writer = std::make_shared<const dds::Entity>(std::move(*w));
  reply_writers_[key] = {writer, ++reply_writer_uses_};
  return writer;
}

Expected<std::size_t> MapService::save(const std::filesystem::path& file) {
  auto saved = saveUncounted(file);
  if (!saved) {
    ++snapshot_failures_;
    std::lock_guard lock(error_mutex_);
    last_snapshot_error_ = saved.error().message;
  }
  return saved;
}

Expected<std::size_t> MapService::saveUncounted(const std::filesystem::path& file) {
  const std::filesystem::path target = file.empty() ? options_.snapshot_path : file;
  if (target.empty()) return makeError("no snapshot path configured or given");
  const ReturnFreeMemory trim;  // the snapshot's buffers (about the file's size)
  const SensorModel model(pipeline_.options().sensor);
  if (file.empty() || file == options_.snapshot_path) {
    // One rotation at a time: a command's save and an autosave must not rotate generations
    // under each other.
    const std::lock_guard lock(save_mutex_);
    const Pipeline::SavedState state = pipeline_.savedState();
    return saveSnapshotKeeping(*state.view, model, pipeline_.options().backend, target,
                               options_.snapshot_keep, state.kernel ? &*state.kernel : nullptr);
  }
  const Pipeline::SavedState state = pipeline_.savedState();
  return saveSnapshot(*state.view, model, pipeline_.options().backend, target,
                      state.kernel ? &*state.kernel : nullptr);
}

void MapService::publishStatus() {
  // A server that appears later (a network partition healed, a second one started with checks
  // bypassed): said in the log once a minute; clients would see two maps.
  if (const auto now = std::chrono::steady_clock::now(); now >= next_alone_check_) {
    next_alone_check_ = now + std::chrono::seconds(60);
    if (const auto others = otherServers(); !others.empty()) {
      spdlog::error("another densemap-server (participant {}) runs on DDS domain {}",
                    others.front(), options_.domain_id);
    }
  }
  const PipelineCounters c = pipeline_.counters();
  const auto view = pipeline_.view();
  densemap_msgs_Status s{};
  s.received = c.received;
  s.integrated = c.integrated;
  s.dropped = c.dropped;
  s.rejected = c.rejected;
  std::vector<std::uint64_t> by_reason(c.rejected_by_reason.begin(), c.rejected_by_reason.end());
  s.rejected_by_reason = dds::borrowSequence<dds_sequence_unsigned_long_long>(by_reason);
  s.last_reject_reason = const_cast<char*>(c.last_reject_reason.c_str());
  s.latency_p50_ms = c.latency_p50_ms;
  s.latency_p99_ms = c.latency_p99_ms;
  s.known_cells = view->knownCells();
  s.map_version = view->version();
  s.memory_bytes = view->memoryBytes();
  s.uptime_s = std::chrono::duration<double>(std::chrono::steady_clock::now() - started_).count();
  const ProcessUsage usage = processUsage();
  s.rss_bytes = usage.rss_bytes;
  s.evicted_blocks = c.evicted_blocks;
  s.evicted_cells = c.evicted_cells;
  s.snapshot_failures = snapshot_failures_.load();
  std::string last_snapshot_error;
  {
    std::lock_guard lock(error_mutex_);
    last_snapshot_error = last_snapshot_error_;
  }
  s.last_snapshot_error = const_cast<char*>(last_snapshot_error.c_str());
  s.cpu_s = usage.cpu_s;
  s.queries_answered = queries_answered_.load();
  s.queries_rejected = queries_rejected_.load();
  std::string last_error;
  {
    std::lock_guard lock(error_mutex_);
    last_error = last_query_error_;
  }
  s.last_query_error = const_cast<char*>(last_error.c_str());
  std::vector<densemap_msgs_SensorStatus> sensors;
  sensors.reserve(c.sensors.size());
  for (const SensorCounters& sc : c.sensors) {
    sensors.push_back({const_cast<char*>(sc.sensor_id.c_str()), sc.received, sc.integrated,
                       sc.dropped, sc.rejected, sc.seq_gaps});
  }
  s.sensors = dds::borrowSequence<dds_sequence_densemap_msgs_SensorStatus>(sensors);
  const Ros2Counters ros = ros2_ ? ros2_->counters() : Ros2Counters{};
  s.ros_enabled = ros2_ != nullptr;
  s.ros_received = ros.received;
  s.ros_submitted = ros.submitted;
  s.ros_rejected = ros.rejected;
  s.ros_no_transform = ros.no_transform;
  std::vector<std::uint64_t> ros_by_reason(ros.rejected_by_reason.begin(),
                                           ros.rejected_by_reason.end());
  s.ros_rejected_by_reason = dds::borrowSequence<dds_sequence_unsigned_long_long>(ros_by_reason);
  s.ros_last_reject = const_cast<char*>(ros.last_reject.c_str());
  s.ros_maps_published = ros.maps_published;
  (void)dds::write(dds_->status_writer, &s);
}

void MapService::publishManifest() {
  const auto view = pipeline_.view();
  densemap_msgs_MapManifest manifest{};
  manifest.version = view->version();
  manifest.resolution = view->grid().resolution();
  manifest.known_cells = view->knownCells();
  (void)dds::write(dds_->manifest_writer, &manifest);
}

Expected<SentMap> MapService::sendMap(const densemap_msgs_RequestId& request) {
  // One version throughout: the tiles are a consistent copy of it.
  const ReturnFreeMemory trim;  // the tiles' buffers and the writer's copies until acked
  const auto view = pipeline_.view();
  const auto tiles = tilesOf(*view);
  std::size_t cells = 0;
  for (const auto& [id, blocks] : tiles) {
    VersionDelta t = cellsOf(*view, blocks);
    cells += t.cells.size();
    densemap_msgs_MapTile tile{};
    tile.request = request;
    tile.tile_id = id;
    tile.version = view->version();
    dds::borrowCells(tile, t);
    // Keep-all: a reader that does not keep up blocks the write; one that stopped ends it.
    if (auto ok = dds::write(dds_->tile_writer, &tile); !ok) {
      return makeError("send-map stopped after " + std::to_string(cells) +
                       " cells: " + ok.error().message);
    }
  }
  return SentMap{.version = view->version(), .tiles = tiles.size(), .cells = cells};
}

}  // namespace densemap::server
