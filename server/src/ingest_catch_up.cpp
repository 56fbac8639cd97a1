// A replica's catch-up (Ingest::catchUp, docs/fleet.md): the scans integrated while it fetched
// its peer's map are kept; the peer's map replaces its own, the kept scans the peer's map lacks
// are integrated into it, and the change is published as one version.
#include <spdlog/spdlog.h>

#include <algorithm>
#include <mutex>

#include "densemap/query/version_delta.hpp"
#include "densemap/server/ingest.hpp"
#include "guarded.hpp"

namespace densemap::server {

Ingest::Latest Ingest::latest() const {
  std::lock_guard lock(latest_mutex_);
  return latest_;
}

void Ingest::keepForCatchUp(const RawScan& raw) {
  if (!keep_scans_.load()) return;
  if (kept_.size() >= kMaxCatchUpScans) {
    kept_overflow_ = true;
    return;
  }
  kept_.push_back(raw);
}

std::future<Expected<std::string>> Ingest::catchUp(std::unique_ptr<OccupancyMap> map,
                                                   std::uint64_t version,
                                                   SensorStamps last_stamps) {
  std::promise<Expected<std::string>> done;
  auto future = done.get_future();
  {
    std::lock_guard lock(catch_up_mutex_);
    if (catch_up_) {
      done.set_value(makeError("a catch-up is under way already"));
      return future;
    }
    catch_up_.emplace(
        PendingCatchUp{std::move(map), version, std::move(last_stamps), std::move(done)});
  }
  if (!running_.load()) applyCatchUp();
  return future;
}

void Ingest::applyCatchUp() {
  std::optional<PendingCatchUp> pending;
  {
    std::lock_guard lock(catch_up_mutex_);
    if (!catch_up_) return;
    pending.swap(catch_up_);
  }
  const auto finish = [&](Expected<std::string> outcome) {
    keep_scans_ = false;
    kept_.clear();
    kept_.shrink_to_fit();
    kept_overflow_ = false;
    pending->done.set_value(std::move(outcome));
  };
  const auto old_view = engine_->view();
  if (pending->version <= old_view->version()) {
    finish(makeError("the peer's map (version " + std::to_string(pending->version) +
                     ") is not ahead of this one (version " + std::to_string(old_view->version()) +
                     ")"));
    return;
  }
  if (kept_overflow_) {
    finish(makeError("more than " + std::to_string(kMaxCatchUpScans) +
                     " scans came while the peer's map was fetched"));
    return;
  }
  // Every sensor the peer has scans of must have its first kept scan in the peer's map: else
  // scans between the two may have reached the peer only (before this server's reader matched
  // the robot's writer).
  for (const auto& [sensor, last] : pending->last_stamps) {
    const auto first = std::find_if(kept_.begin(), kept_.end(),
                                    [&](const RawScan& r) { return r.sensor_id == sensor; });
    if (first != kept_.end() && first->stamp_ns > last) {
      pending->done.set_value(makeError(std::string(kCatchUpGap) + " the first scan kept of '" +
                                        sensor + "' (stamped " + std::to_string(first->stamp_ns) +
                                        " ns, the peer's last " + std::to_string(last) + " ns)"));
      return;
    }
  }
  PipelineOptions own = options_;
  own.warm_up = false;
  auto engine = Engine::create(own, std::move(pending->map), pending->version);
  if (!engine) {
    finish(std::unexpected(engine.error()));
    return;
  }
  // The kept scans the peer's map lacks, in the order they came.
  SensorStamps stamps = pending->last_stamps;
  std::size_t integrated = 0, skipped = 0;
  for (const RawScan& raw : kept_) {
    auto it = std::find_if(stamps.begin(), stamps.end(),
                           [&](const auto& s) { return s.first == raw.sensor_id; });
    if (it != stamps.end() && raw.stamp_ns <= it->second) {
      ++skipped;
      continue;
    }
    std::expected<IntegrationResult, Rejection> outcome;
    arena_.execute([&] { outcome = (*engine)->integrate(raw); });
    if (!outcome) continue;  // rejected here as the peer rejected it
    ++integrated;
    if (it != stamps.end()) {
      it->second = raw.stamp_ns;
    } else if (stamps.size() < SensorTally::kMaxSensors) {
      stamps.emplace_back(raw.sensor_id, raw.stamp_ns);
    }
  }
  const auto new_view = (*engine)->view();
  std::vector<std::uint64_t> blocks;
  old_view->forEachBlock([&](std::uint64_t key, const VoxelBlock&) { blocks.push_back(key); });
  new_view->forEachBlock([&](std::uint64_t key, const VoxelBlock&) { blocks.push_back(key); });
  std::sort(blocks.begin(), blocks.end());
  blocks.erase(std::unique(blocks.begin(), blocks.end()), blocks.end());
  IntegrationResult result;
  result.changes = diffVersions(*old_view, *new_view, blocks).changes();
  result.written_blocks = std::move(blocks);
  result.base_version = old_view->version();
  result.new_version = new_view->version();
  {
    const std::unique_lock lock(engine_swap_);
    engine_ = std::move(*engine);
  }
  cancelReintegration();
  if (history_) history_->restart(new_view);
  last_stamps_ = std::move(stamps);
  const std::string message =
      "caught up: the peer's map at version " + std::to_string(pending->version) + ", then " +
      std::to_string(integrated) + " scans it lacked (" + std::to_string(skipped) +
      " kept scans were in it); version " + std::to_string(new_view->version());
  published(result);
  finish(message);
}

}  // namespace densemap::server
