#include "publisher.hpp"

#include "densemap/query/version_delta.hpp"
#include "densemap/wire/delta_wire.hpp"
#include "densemap_msgs.h"

namespace densemap::server {

namespace {

// Beyond this many versions waiting for the publish thread, their deltas are coalesced.
constexpr std::size_t kMaxPendingVersions = 8;

}  // namespace

void Publisher::onIntegrated(const IntegrationResult& r,
                             const std::shared_ptr<const MapView>& view) {
  // On the pipeline's worker: a small event now, everything else on the publish thread.
  if (ros2_) ros2_->onVersion(r, view);
  if (foxglove_) foxglove_->onVersion(r, view);
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
  (void)dds::write(writers_.events, &event);
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
    std::lock_guard lock(mutex_);
    versions_.push_back(std::move(v));
  }
  cv_.notify_one();
}

void Publisher::publishWaiting(std::chrono::steady_clock::time_point until,
                               const std::atomic<bool>& running) {
  std::deque<Version> versions;
  {
    std::unique_lock lock(mutex_);
    cv_.wait_until(lock, until, [&] { return !versions_.empty() || !running.load(); });
    versions.swap(versions_);
  }
  publishDeltas(versions);
}

void Publisher::publishDeltas(std::deque<Version>& versions) {
  if (versions.empty()) return;
  dds_publication_matched_status_t matched{};
  const bool wanted = dds_get_publication_matched_status(writers_.deltas.get(), &matched) >= 0 &&
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
    (void)dds::write(writers_.deltas, &msg);
    delta_base_ = v.view;
  }
  versions.clear();
}

void Publisher::publishManifest() {
  const auto view = ingest_.view();
  densemap_msgs_MapManifest manifest{};
  manifest.version = view->version();
  manifest.resolution = view->grid().resolution();
  manifest.known_cells = view->knownCells();
  if (const auto& box = ingest_.options().bounds) {
    manifest.bounded = true;
    manifest.min_x = box->first.x();
    manifest.min_y = box->first.y();
    manifest.min_z = box->first.z();
    manifest.max_x = box->second.x();
    manifest.max_y = box->second.y();
    manifest.max_z = box->second.z();
  }
  (void)dds::write(writers_.manifest, &manifest);
}

}  // namespace densemap::server
