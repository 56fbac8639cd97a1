#include "densemap/server/map_service.hpp"

#include <spdlog/spdlog.h>

#include <algorithm>
#include <thread>
#include <utility>
#include <vector>

#include "command_room.hpp"
#include "densemap/server/export_path.hpp"
#include "densemap/wire/correction_wire.hpp"
#include "densemap/wire/topics.hpp"
#include "densemap_msgs.h"
#include "guarded.hpp"
#include "publisher.hpp"
#include "query_room.hpp"
#include "replies.hpp"
#include "request_tasks.hpp"
#include "snapshot_saver.hpp"
#include "status_room.hpp"

namespace densemap::server {

namespace {

// Attachment tags of the service waitset.
constexpr dds_attach_t kPointTag = 1, kBboxTag = 2, kRayTag = 3, kCmdTag = 4, kScanTag = 5,
                       kMapTag = 6, kDistanceTag = 7, kPathTag = 8, kBoxesTag = 9,
                       kDistanceBoxTag = 10, kCorrectionTag = 11;

}  // namespace

struct MapService::Dds {
  dds::Entity participant;
  dds::Topics topics;
  dds::Entity scan_reader, correction_reader, point_reader, bbox_reader, ray_reader, cmd_reader,
      map_reader;
  dds::Entity distance_reader, path_reader, boxes_reader, distance_box_reader;
  // Replies go out through writers made per asking client (ReplyWriters).
  dds::Entity manifest_writer, tile_writer, delta_writer, event_writer, status_writer;
  std::optional<dds::WaitSet> ingest_waitset;
  std::optional<dds::WaitSet> service_waitset;
  dds::Entity status_probe;  // reads densemap/status: matches every server's status writer
};

Expected<std::unique_ptr<MapService>> MapService::create(Ingest& ingest,
                                                         const ServiceOptions& options) {
  std::unique_ptr<MapService> service(new MapService(ingest, options));
  auto& d = *service->dds_;
  auto participant =
      dds::createParticipant({options.domain_id, options.network_interface, options.security});
  if (!participant) return std::unexpected(participant.error());
  d.participant = std::move(*participant);
  Expected<void> status;
  auto topics = dds::Topics::create(d.participant, options.instance);
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
  reader(d.scan_reader, d.topics.scan, dds::kScanQos);
  reader(d.correction_reader, d.topics.pose_correction, dds::kCorrectionQos);
  reader(d.point_reader, d.topics.point_request, requests);
  reader(d.bbox_reader, d.topics.bbox_request, requests);
  reader(d.ray_reader, d.topics.ray_request, requests);
  reader(d.distance_reader, d.topics.distance_request, requests);
  reader(d.path_reader, d.topics.path_request, requests);
  reader(d.boxes_reader, d.topics.boxes_request, requests);
  reader(d.distance_box_reader, d.topics.distance_box_request, requests);
  reader(d.cmd_reader, d.topics.command_request, dds::kCommandQos);
  reader(d.map_reader, d.topics.map_request, dds::kCommandQos);
  writer(d.manifest_writer, d.topics.manifest, dds::kLatestStateQos);
  writer(d.tile_writer, d.topics.tiles, dds::kTileQos);
  writer(d.delta_writer, d.topics.delta, dds::kDeltaWriterQos);
  writer(d.event_writer, d.topics.events, dds::kEventWriterQos);
  writer(d.status_writer, d.topics.status, dds::kLatestStateQos);
  if (!status) return std::unexpected(status.error());

  auto ingest_ws = dds::WaitSet::create(d.participant);
  auto service_ws = dds::WaitSet::create(d.participant);
  if (!ingest_ws || !service_ws) return makeError("cannot create DDS waitsets");
  d.ingest_waitset.emplace(std::move(*ingest_ws));
  d.service_waitset.emplace(std::move(*service_ws));
  for (auto [r, tag] :
       {std::pair{&d.point_reader, kPointTag}, std::pair{&d.bbox_reader, kBboxTag},
        std::pair{&d.ray_reader, kRayTag}, std::pair{&d.cmd_reader, kCmdTag},
        std::pair{&d.map_reader, kMapTag}, std::pair{&d.distance_reader, kDistanceTag},
        std::pair{&d.path_reader, kPathTag}, std::pair{&d.boxes_reader, kBoxesTag},
        std::pair{&d.distance_box_reader, kDistanceBoxTag}}) {
    if (auto ok = d.service_waitset->attachReader(*r, tag); !ok) return std::unexpected(ok.error());
  }
  for (auto [r, tag] :
       {std::pair{&d.scan_reader, kScanTag}, std::pair{&d.correction_reader, kCorrectionTag}}) {
    if (auto ok = d.ingest_waitset->attachReader(*r, tag); !ok) return std::unexpected(ok.error());
  }
  if (options.ros2) {
    auto bridge = Ros2Bridge::create(ingest, d.participant, *options.ros2);
    if (!bridge) return std::unexpected(bridge.error());
    service->ros2_ = std::move(*bridge);
  }
  if (options.foxglove) {
    auto room = FoxgloveRoom::create(*options.foxglove, ingest.view());
    if (!room) return std::unexpected(room.error());
    service->foxglove_ = std::move(*room);
  }
  service->makeRooms();
  ingest.setPublisher([p = service->publisher_.get()](const IntegrationResult& r,
                                                      const std::shared_ptr<const MapView>& v) {
    p->onIntegrated(r, v);
  });
  return service;
}

void MapService::makeRooms() {
  Dds& d = *dds_;
  replies_ = std::make_unique<ReplyWriters>(d.participant, d.topics);
  queries_ = std::make_unique<QueryRoom>(
      ingest_,
      QueryRoom::Readers{d.point_reader, d.bbox_reader, d.ray_reader, d.distance_reader,
                         d.path_reader, d.boxes_reader, d.distance_box_reader},
      *replies_, *tasks_, *stats_, options_.max_query_cells);
  commands_ = std::make_unique<CommandRoom>(
      ingest_, CommandRoom::Endpoints{d.cmd_reader, d.map_reader, d.tile_writer}, *replies_,
      *tasks_, *stats_, *saver_, exportDirectory(options_.export_dir, options_.snapshot_path));
  publisher_ = std::make_unique<Publisher>(
      ingest_, Publisher::Writers{d.event_writer, d.delta_writer, d.manifest_writer}, ros2_.get(),
      foxglove_.get());
  status_ = std::make_unique<StatusRoom>(
      ingest_, d.status_writer, d.participant, d.status_probe, options_.domain_id,
      StatusRoom::Sources{*stats_, *saver_, ros2_.get(), foxglove_.get()});
}

Expected<void> MapService::checkAlone(std::chrono::milliseconds discovery) const {
  const auto deadline = std::chrono::steady_clock::now() + discovery;
  while (true) {
    if (const auto others = otherServers(dds_->participant, dds_->status_probe); !others.empty()) {
      return makeError(std::string(kAnotherServer) + " (participant " + others.front() +
                       ") already runs on DDS domain " + std::to_string(options_.domain_id) +
                       ": two servers on one domain would answer the same clients with two "
                       "maps; stop it, or give this one another dds.domain_id / --domain-id, or "
                       "a dds.instance of its own (a replica)");
    }
    if (std::chrono::steady_clock::now() >= deadline) return {};
    std::this_thread::sleep_for(std::chrono::milliseconds(20));
  }
}

MapService::MapService(Ingest& ingest, const ServiceOptions& options)
    : ingest_(ingest),
      options_(options),
      dds_(std::make_unique<Dds>()),
      stats_(std::make_unique<RequestStats>()),
      tasks_(std::make_unique<RequestTasks>(options.query_threads, options.request_budget_bytes)),
      saver_(
          std::make_unique<SnapshotSaver>(ingest, options.snapshot_path, options.snapshot_keep)) {}

MapService::~MapService() { stop(); }

void MapService::start() {
  if (running_.exchange(true)) return;
  scan_taker_ = std::thread([this] { ingestLoop(); });
  service_ = std::thread([this] { serviceLoop(); });
  publish_ = std::thread([this] { publishLoop(); });
  if (ros2_) ros2_->start();
  if (foxglove_) foxglove_->start();
}

void MapService::stop() {
  if (!running_.exchange(false)) return;
  if (ros2_) ros2_->stop();  // no more ROS clouds
  dds_->ingest_waitset->wake();
  dds_->service_waitset->wake();
  publisher_->wake();
  if (scan_taker_.joinable()) scan_taker_.join();
  if (service_.joinable()) service_.join();
  tasks_->wait();
  if (publish_.joinable()) publish_.join();
  if (foxglove_) foxglove_->stop();  // after the last version and status went to it
}

Expected<std::size_t> MapService::save(const std::filesystem::path& file) {
  return saver_->save(file);
}

void MapService::ingestLoop() {
  // Only takes and enqueues: validation and integration happen in the pipeline.
  while (running_.load()) {
    dds_->ingest_waitset->wait(std::chrono::milliseconds(200));
    guarded("scan intake", [&] {
      dds::takeAll<densemap_msgs_Scan>(dds_->scan_reader, [&](const densemap_msgs_Scan& msg) {
        RawScan raw;
        raw.sensor_id = dds::text(msg.sensor_id);
        raw.seq = msg.seq;
        raw.stamp_ns = msg.stamp_ns;
        for (int i = 0; i < 3; ++i) raw.t_world_sensor[i] = msg.T_world_sensor.t[i];
        for (int i = 0; i < 4; ++i) raw.q_world_sensor[i] = msg.T_world_sensor.q[i];
        raw.xyz.assign(msg.points._buffer, msg.points._buffer + msg.points._length);
        raw.intensity.assign(msg.intensity._buffer, msg.intensity._buffer + msg.intensity._length);
        ingest_.submit(std::move(raw));
      });
      dds::takeAll<densemap_msgs_PoseCorrection>(
          dds_->correction_reader, [&](const densemap_msgs_PoseCorrection& msg) {
            auto correction = dds::correctionFromWire(msg);
            auto ok = correction ? ingest_.correct(std::move(*correction))
                                 : ingest_.refuseCorrection(correction.error().message);
            if (!ok) spdlog::warn("{}", ok.error().message);
          });
    });
  }
}

void MapService::serviceLoop() {
  while (running_.load()) {
    dds_->service_waitset->wait(std::chrono::milliseconds(100));
    guarded("requests", [&] {
      queries_->take();
      commands_->answer();
    });
  }
}

void MapService::publishLoop() {
  auto next_status = std::chrono::steady_clock::now();
  const auto autosave_period = std::chrono::duration_cast<std::chrono::steady_clock::duration>(
      std::chrono::duration<double>(options_.autosave_period_s));
  auto next_save = next_status + autosave_period;
  const bool autosave = options_.autosave_period_s > 0 && !options_.snapshot_path.empty();
  std::uint64_t saved_version = ingest_.view()->version();  // what the file already holds
  while (running_.load()) {
    guarded("publishing", [&] {
      publisher_->publishWaiting(autosave ? std::min(next_status, next_save) : next_status,
                                 running_);
      const auto now = std::chrono::steady_clock::now();
      heartbeat_ = now.time_since_epoch().count();
      if (now >= next_status) {
        next_status = now + std::chrono::seconds(1);  // first: a turn that throws waits too
        status_->publish();
        publisher_->publishManifest();
        // Requests served and none in flight: the heap goes back to the OS (RSS stayed ~850 MB
        // after a flood until a save trimmed it).
        tasks_->trimIfIdle();
      }
      // Autosave only a changed map: a daemon idle for months does not rewrite the same file.
      if (autosave && now >= next_save) {
        next_save = now + autosave_period;  // first: a save that throws waits a period too
        const std::uint64_t version = ingest_.view()->version();
        auto pause = autosave_period;
        if (version != saved_version) {
          const auto began = std::chrono::steady_clock::now();
          if (auto ok = saver_->save(); !ok) {
            spdlog::warn("autosave failed: {}", ok.error().message);  // counted by the saver
          } else {
            saved_version = version;
          }
          // A short period on a large map would mean back-to-back full rewrites: saving takes
          // at most a fifth of the time.
          pause = std::max(pause, 4 * (std::chrono::steady_clock::now() - began));
        }
        next_save = std::chrono::steady_clock::now() + pause;
      }
    });
  }
  guarded("publishing", [&] {
    publisher_->publishWaiting(std::chrono::steady_clock::now(), running_);  // what is left
    status_->publish();
    publisher_->publishManifest();
  });
}

}  // namespace densemap::server
