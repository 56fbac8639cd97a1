#include "map_service.hpp"

#include <cmath>
#include <limits>
#include <unordered_map>

#include "densemap/dds/topics.hpp"
#include "densemap/pipeline/map_queries.hpp"
#include "densemap_msgs.h"
#include "snapshot.hpp"

namespace densemap::server {

std::uint64_t tileOf(const VoxelKey& k) {
  return std::uint64_t{static_cast<std::uint16_t>(k.x >> 5)} |
         (std::uint64_t{static_cast<std::uint16_t>(k.y >> 5)} << 11) |
         (std::uint64_t{static_cast<std::uint16_t>(k.z >> 5)} << 22);
}

namespace {

constexpr std::int32_t kOk = 0, kInvalid = 1, kInternal = 2;

// Attachment tags of the service waitset.
constexpr dds_attach_t kPointTag = 1, kBboxTag = 2, kRayTag = 3, kCmdTag = 4, kScanTag = 5;

Point3f toPoint(const float (&v)[3]) { return {v[0], v[1], v[2]}; }

}  // namespace

struct MapService::Dds {
  dds::Entity participant;
  dds::Topics topics;
  dds::Entity scan_reader, point_reader, bbox_reader, ray_reader, cmd_reader;
  dds::Entity point_writer, bbox_writer, ray_writer, cmd_writer, manifest_writer, tile_writer,
      delta_writer, status_writer;
  std::optional<dds::WaitSet> ingest_waitset;
  std::optional<dds::WaitSet> service_waitset;
};

Expected<std::unique_ptr<MapService>> MapService::create(Pipeline& pipeline,
                                                         const ServiceOptions& options) {
  std::unique_ptr<MapService> service(new MapService(pipeline, options));
  auto& d = *service->dds_;
  auto participant = dds::createParticipant(options.domain_id, options.network_interface);
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
  const dds::QosSpec requests = dds::kRequestQos;
  reader(d.scan_reader, d.topics.scan, {.depth = 4});
  reader(d.point_reader, d.topics.point_request, requests);
  reader(d.bbox_reader, d.topics.bbox_request, requests);
  reader(d.ray_reader, d.topics.ray_request, requests);
  reader(d.cmd_reader, d.topics.command_request, dds::kCommandQos);
  writer(d.point_writer, d.topics.point_reply, requests);
  writer(d.bbox_writer, d.topics.bbox_reply, requests);
  writer(d.ray_writer, d.topics.ray_reply, requests);
  writer(d.cmd_writer, d.topics.command_reply, dds::kCommandQos);
  writer(d.manifest_writer, d.topics.manifest, dds::kLatestStateQos);
  writer(d.tile_writer, d.topics.tiles, dds::kLatestStateQos);
  writer(d.delta_writer, d.topics.delta, {.depth = 32});
  writer(d.status_writer, d.topics.status, dds::kLatestStateQos);
  if (!status) return std::unexpected(status.error());

  auto ingest_ws = dds::WaitSet::create(d.participant);
  auto service_ws = dds::WaitSet::create(d.participant);
  if (!ingest_ws || !service_ws) return makeError("cannot create DDS waitsets");
  d.ingest_waitset.emplace(std::move(*ingest_ws));
  d.service_waitset.emplace(std::move(*service_ws));
  for (auto [r, tag] : {std::pair{&d.point_reader, kPointTag}, std::pair{&d.bbox_reader, kBboxTag},
                        std::pair{&d.ray_reader, kRayTag}, std::pair{&d.cmd_reader, kCmdTag}}) {
    if (auto ok = d.service_waitset->attachReader(*r, tag); !ok) return std::unexpected(ok.error());
  }
  if (auto ok = d.ingest_waitset->attachReader(d.scan_reader, kScanTag); !ok) {
    return std::unexpected(ok.error());
  }
  pipeline.setPublisher(
      [s = service.get()](const IntegrationResult& r, const std::shared_ptr<const MapView>& v) {
        s->onIntegrated(r, v);
      });
  // The map loaded from a snapshot is published as tiles right away.
  pipeline.view()->forEachKnown(
      [&](const VoxelKey& k, float) { service->dirty_tiles_.insert(tileOf(k)); });
  return service;
}

MapService::MapService(Pipeline& pipeline, const ServiceOptions& options)
    : pipeline_(pipeline), options_(options), dds_(std::make_unique<Dds>()) {}

MapService::~MapService() { stop(); }

void MapService::start() {
  if (running_.exchange(true)) return;
  ingest_ = std::thread([this] { ingestLoop(); });
  service_ = std::thread([this] { serviceLoop(); });
}

void MapService::stop() {
  if (!running_.exchange(false)) return;
  dds_->ingest_waitset->wake();
  dds_->service_waitset->wake();
  if (ingest_.joinable()) ingest_.join();
  if (service_.joinable()) service_.join();
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
  auto next_status = std::chrono::steady_clock::now();
  auto next_tiles = next_status;
  auto next_save = next_status + std::chrono::duration_cast<std::chrono::steady_clock::duration>(
                                     std::chrono::duration<double>(options_.autosave_period_s));
  while (running_.load()) {
    dds_->service_waitset->wait(std::chrono::milliseconds(100));
    answerPointQueries();
    answerBboxQueries();
    answerRayQueries();
    answerCommands();
    const auto now = std::chrono::steady_clock::now();
    if (now >= next_status) {
      publishStatus();
      next_status = now + std::chrono::seconds(1);
    }
    if (now >= next_tiles) {
      publishTiles();
      next_tiles = now + std::chrono::seconds(1);
    }
    if (options_.autosave_period_s > 0 && !options_.snapshot_path.empty() && now >= next_save) {
      if (auto ok = save(); !ok) noteBadRequest("autosave: " + ok.error().message);
      next_save = now + std::chrono::duration_cast<std::chrono::steady_clock::duration>(
                            std::chrono::duration<double>(options_.autosave_period_s));
    }
  }
  publishTiles();
  publishStatus();
}

void MapService::onIntegrated(const IntegrationResult& r, const std::shared_ptr<const MapView>&) {
  std::vector<std::uint16_t> keys;
  std::vector<float> values;
  keys.reserve(r.changes.size() * 3);
  values.reserve(r.changes.size());
  {
    std::lock_guard lock(dirty_mutex_);
    for (const CellChange& c : r.changes) {
      keys.insert(keys.end(), {c.key.x, c.key.y, c.key.z});
      values.push_back(c.known ? c.log_odds : std::numeric_limits<float>::quiet_NaN());
      dirty_tiles_.insert(tileOf(c.key));
    }
  }
  densemap_msgs_MapDelta delta{};
  delta.base_version = r.base_version;
  delta.new_version = r.new_version;
  delta.sensor_id = const_cast<char*>(r.sensor_id.c_str());
  delta.scan_seq = r.scan_seq;
  delta.scan_stamp_ns = r.stamp_ns;
  delta.from_scan = r.from_scan;
  delta.keys = dds::borrowSequence<dds_sequence_unsigned_short>(keys);
  delta.log_odds = dds::borrowSequence<dds_sequence_float>(values);
  (void)dds::write(dds_->delta_writer, &delta);
}

void MapService::noteBadRequest(const std::string& error) {
  ++queries_rejected_;
  std::lock_guard lock(error_mutex_);
  last_query_error_ = error;
}

void MapService::answerPointQueries() {
  dds::takeAll<densemap_msgs_PointQueryRequest>(
      dds_->point_reader, [&](const densemap_msgs_PointQueryRequest& req) {
        densemap_msgs_PointQueryReply rep{};
        rep.id = req.id;
        std::string error;
        std::vector<float> values;
        std::vector<std::uint8_t> states;
        const auto view = pipeline_.view();
        rep.map_version = view->version();
        if (req.points._length % 3 != 0) {
          error = "point query length is not a multiple of 3";
        } else if (req.points._length / 3 > 10'000'000) {
          error = "more than 10 million query points";
        } else {
          const std::size_t n = req.points._length / 3;
          values.resize(n, std::numeric_limits<float>::quiet_NaN());
          states.resize(n, 0);
          for (std::size_t i = 0; i < n; ++i) {
            const Point3f p(req.points._buffer[3 * i], req.points._buffer[3 * i + 1],
                            req.points._buffer[3 * i + 2]);
            const auto key = p.allFinite() ? view->grid().pointToKey(p) : std::nullopt;
            const auto v = key ? view->logOdds(*key) : std::nullopt;
            if (v) values[i] = *v;
            states[i] = static_cast<std::uint8_t>(cellState(v));
          }
        }
        rep.status = error.empty() ? kOk : kInvalid;
        rep.error = const_cast<char*>(error.c_str());
        rep.log_odds = dds::borrowSequence<dds_sequence_float>(values);
        rep.state = dds::borrowSequence<dds_sequence_octet>(states);
        if (!error.empty()) noteBadRequest(error);
        ++queries_answered_;
        (void)dds::write(dds_->point_writer, &rep);
      });
}

void MapService::answerBboxQueries() {
  dds::takeAll<densemap_msgs_BboxQueryRequest>(
      dds_->bbox_reader, [&](const densemap_msgs_BboxQueryRequest& req) {
        densemap_msgs_BboxQueryReply rep{};
        rep.id = req.id;
        const auto view = pipeline_.view();
        rep.map_version = view->version();
        auto result = queryBox(*view, toPoint(req.min), toPoint(req.max), options_.max_query_cells,
                               std::min<std::uint32_t>(req.max_centers, 1'000'000));
        std::string error;
        std::vector<float> centers;
        if (result) {
          rep.occupied = result->occupied;
          rep.free_cells = result->free;
          rep.unknown = result->unknown;
          for (const auto& c : result->occupied_centers)
            centers.insert(centers.end(), {c.x(), c.y(), c.z()});
        } else {
          error = result.error().message;
          noteBadRequest(error);
        }
        rep.status = error.empty() ? kOk : kInvalid;
        rep.error = const_cast<char*>(error.c_str());
        rep.occupied_centers = dds::borrowSequence<dds_sequence_float>(centers);
        ++queries_answered_;
        (void)dds::write(dds_->bbox_writer, &rep);
      });
}

void MapService::answerRayQueries() {
  dds::takeAll<densemap_msgs_RayQueryRequest>(
      dds_->ray_reader, [&](const densemap_msgs_RayQueryRequest& req) {
        densemap_msgs_RayQueryReply rep{};
        rep.id = req.id;
        const auto view = pipeline_.view();
        rep.map_version = view->version();
        auto result = castRay(*view, toPoint(req.origin), toPoint(req.direction), req.max_range);
        std::string error;
        if (result) {
          rep.hit = result->hit;
          for (int i = 0; i < 3; ++i) rep.hit_point[i] = result->hit_center[i];
          rep.distance = result->distance;
        } else {
          error = result.error().message;
          noteBadRequest(error);
        }
        rep.status = error.empty() ? kOk : kInvalid;
        rep.error = const_cast<char*>(error.c_str());
        ++queries_answered_;
        (void)dds::write(dds_->ray_writer, &rep);
      });
}

void MapService::answerCommands() {
  dds::takeAll<densemap_msgs_CommandRequest>(
      dds_->cmd_reader, [&](const densemap_msgs_CommandRequest& req) {
        Expected<std::string> outcome =
            makeError("unknown command kind " + std::to_string(req.kind));
        const VoxelGrid& grid = pipeline_.view()->grid();
        if (req.kind == 0 || req.kind == 1) {
          VoxelKey lo{0, 0, 0}, hi{65535, 65535, 65535};
          bool valid = true;
          if (req.kind == 1) {
            const Point3f mn = toPoint(req.min), mx = toPoint(req.max);
            const auto klo = mn.allFinite() ? grid.pointToKey(mn) : std::nullopt;
            const auto khi = mx.allFinite() ? grid.pointToKey(mx) : std::nullopt;
            if (!klo || !khi) {
              outcome = makeError("clear-bbox corner is NaN/Inf or outside the map");
              valid = false;
            } else if ((mn.array() > mx.array()).any()) {
              outcome = makeError("inverted box: min > max on some axis");
              valid = false;
            } else {
              lo = *klo;
              hi = *khi;
            }
          }
          if (valid) {
            auto future = pipeline_.command(
                [lo, hi](OccupancyMap& map, CellChanges& changes) -> Expected<std::string> {
                  return "erased " + std::to_string(map.clearBox(lo, hi, &changes)) + " cells";
                });
            outcome = future.get();
          }
        } else if (req.kind == 2) {
          const std::string path = req.path != nullptr ? req.path : "";
          auto saved = save(path);
          if (saved)
            outcome = "saved " + std::to_string(*saved) + " bytes";
          else
            outcome = std::unexpected(saved.error());
        }
        densemap_msgs_CommandReply rep{};
        rep.id = req.id;
        rep.map_version = pipeline_.view()->version();
        const std::string error = outcome ? "" : outcome.error().message;
        const std::string detail = outcome ? *outcome : "";
        if (!outcome) noteBadRequest(error);
        rep.status = outcome ? kOk : kInvalid;
        rep.error = const_cast<char*>(error.c_str());
        rep.detail = const_cast<char*>(detail.c_str());
        (void)dds::write(dds_->cmd_writer, &rep);
      });
}

Expected<std::size_t> MapService::save(const std::filesystem::path& file) {
  const std::filesystem::path target = file.empty() ? options_.snapshot_path : file;
  if (target.empty()) return makeError("no snapshot path configured or given");
  return saveSnapshot(*pipeline_.view(), SensorModel(pipeline_.options().sensor),
                      pipeline_.options().backend, target);
}

void MapService::publishStatus() {
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
  s.memory_bytes = view->blockCount() * (sizeof(VoxelBlock) + 48);
  s.uptime_s = std::chrono::duration<double>(std::chrono::steady_clock::now() - started_).count();
  s.queries_answered = queries_answered_.load();
  s.queries_rejected = queries_rejected_.load();
  std::string last_error;
  {
    std::lock_guard lock(error_mutex_);
    last_error = last_query_error_;
  }
  s.last_query_error = const_cast<char*>(last_error.c_str());
  (void)dds::write(dds_->status_writer, &s);
}

void MapService::publishTiles() {
  std::set<std::uint64_t> dirty;
  {
    std::lock_guard lock(dirty_mutex_);
    dirty.swap(dirty_tiles_);
  }
  const auto view = pipeline_.view();
  if (dirty.empty() && manifest_published_) return;
  if (!dirty.empty()) {
    std::unordered_map<std::uint64_t, std::pair<std::vector<std::uint16_t>, std::vector<float>>>
        tiles;
    for (const auto id : dirty) tiles[id];
    // Whole tiles from the latest version, so a late joiner's keep-last-1 copy is complete.
    view->forEachKnown([&](const VoxelKey& k, float v) {
      const auto it = tiles.find(tileOf(k));
      if (it == tiles.end()) return;
      it->second.first.insert(it->second.first.end(), {k.x, k.y, k.z});
      it->second.second.push_back(v);
    });
    for (auto& [id, cells] : tiles) {
      if (cells.second.empty()) {
        known_tiles_.erase(id);
      } else {
        known_tiles_.insert(id);
      }
      densemap_msgs_MapTile tile{};
      tile.tile_id = id;
      tile.version = view->version();
      tile.keys = dds::borrowSequence<dds_sequence_unsigned_short>(cells.first);
      tile.log_odds = dds::borrowSequence<dds_sequence_float>(cells.second);
      (void)dds::write(dds_->tile_writer, &tile);
    }
  }
  densemap_msgs_MapManifest manifest{};
  manifest.version = view->version();
  manifest.resolution = view->grid().resolution();
  manifest.known_cells = view->knownCells();
  manifest.tile_count = static_cast<std::uint32_t>(known_tiles_.size());
  (void)dds::write(dds_->manifest_writer, &manifest);
  manifest_published_ = true;
}

}  // namespace densemap::server
