#include "densemap/history/scan_history.hpp"

#include <algorithm>

#include "densemap/geometry/block_layout.hpp"
#include "densemap/store/snapshot.hpp"
#include "densemap/query/version_delta.hpp"

namespace densemap {

Expected<void> checkCorrection(const PoseCorrection& correction, const ScanLimits& limits) {
  if (auto ok = checkSensorId(correction.sensor_id); !ok) {
    return makeError("pose correction: " + ok.error().message);
  }
  if (correction.poses.size() > kMaxCorrectedPoses) {
    return makeError("pose correction: " + std::to_string(correction.poses.size()) +
                     " poses, more than " + std::to_string(kMaxCorrectedPoses));
  }
  for (std::size_t i = 0; i < correction.poses.size(); ++i) {
    const CorrectedPose& p = correction.poses[i];
    if (auto ok = checkScanPose(p.t, p.q, limits); !ok) {
      return makeError("pose correction: pose " + std::to_string(i) + ": " + ok.error().message);
    }
  }
  return {};
}

Expected<std::unique_ptr<ScanHistory>> ScanHistory::create(const HistoryOptions& options,
                                                           std::shared_ptr<const MapView> base) {
  if (options.checkpoint_every < 1 || options.checkpoint_every > 1'000'000) {
    return makeError("history: checkpoint_every must be in 1..1000000");
  }
  if (options.max_checkpoints < 1 || options.max_checkpoints > 1024) {
    return makeError("history: max_checkpoints must be in 1..1024");
  }
  auto store = ScanStore::create(options.store);
  if (!store) return makeError("history: " + store.error().message);
  auto history = std::unique_ptr<ScanHistory>(new ScanHistory(options, std::move(*store)));
  history->checkpoints_.push_back({history->store_->end(), std::move(base)});
  return history;
}

ScanHistory::ScanHistory(const HistoryOptions& options, std::unique_ptr<ScanStore> store)
    : options_(options), store_(std::move(store)) {}

void ScanHistory::dropOldestCheckpoint() {
  checkpoints_.erase(checkpoints_.begin());
  store_->dropBefore(checkpoints_.front().index);
}

Expected<void> ScanHistory::record(const RawScan& scan, std::shared_ptr<const MapView> view) {
  auto index = store_->append(scan);
  {
    const std::lock_guard lock(mutex_);
    // A full store gives up its oldest checkpoint and the scans before the next one, while
    // one is left to give up.
    while (!index && checkpoints_.size() > 1 && store_->bytes() > 0) {
      dropOldestCheckpoint();
      index = store_->append(scan);
    }
  }
  if (!index) {
    restart(std::move(view));
    return makeError(index.error().message + "; corrections reach only later scans");
  }
  const std::lock_guard lock(mutex_);
  if (store_->end() - checkpoints_.back().index >= options_.checkpoint_every) {
    checkpoints_.push_back({store_->end(), std::move(view)});
    while (checkpoints_.size() > options_.max_checkpoints) dropOldestCheckpoint();
  }
  return {};
}

void ScanHistory::restart(std::shared_ptr<const MapView> view) {
  const std::lock_guard lock(mutex_);
  store_->clear();
  checkpoints_.clear();
  checkpoints_.push_back({store_->end(), std::move(view)});
}

CorrectionOutcome ScanHistory::correct(const PoseCorrection& correction) {
  CorrectionOutcome out;
  for (const CorrectedPose& p : correction.poses) {
    const auto index = store_->find(correction.sensor_id, p.stamp_ns);
    if (!index || !store_->setPose(*index, p.t, p.q)) {
      ++out.unmatched;
      continue;
    }
    ++out.corrected;
    out.earliest = std::min(out.earliest.value_or(*index), *index);
  }
  return out;
}

std::optional<Checkpoint> ScanHistory::checkpointBefore(std::uint64_t index) const {
  const std::lock_guard lock(mutex_);
  std::optional<Checkpoint> found;
  for (const Checkpoint& c : checkpoints_) {
    if (c.index > index) break;
    found = c;
  }
  return found;
}

bool ScanHistory::hasCheckpointAt(std::uint64_t index) const {
  const std::lock_guard lock(mutex_);
  return std::any_of(checkpoints_.begin(), checkpoints_.end(),
                     [&](const Checkpoint& c) { return c.index == index; });
}

void ScanHistory::replaceCheckpoints(const std::vector<Checkpoint>& rebuilt) {
  const std::lock_guard lock(mutex_);
  for (Checkpoint& c : checkpoints_) {
    for (const Checkpoint& r : rebuilt) {
      if (r.index == c.index) c.view = r.view;
    }
  }
}

std::size_t ScanHistory::checkpoints() const {
  const std::lock_guard lock(mutex_);
  return checkpoints_.size();
}

std::uint64_t ScanHistory::oldestCorrectable() const {
  const std::lock_guard lock(mutex_);
  return checkpoints_.front().index;
}

Expected<std::unique_ptr<Reintegration>> Reintegration::create(const PipelineOptions& options,
                                                               const Checkpoint& from) {
  if (options.kernel || options.decay) {
    return makeError("pose corrections need a log_odds map without decay");
  }
  auto map = mapOfView(*from.view, SensorModel(options.sensor), options.backend);
  if (!map) return std::unexpected(map.error());
  PipelineOptions own = options;
  own.versioned_views = true;  // the checkpoints taken on the way stay valid
  own.warm_up = false;
  own.collect_changes = false;
  auto engine = Engine::create(own, std::move(*map), from.view->version());
  if (!engine) return std::unexpected(engine.error());
  return std::unique_ptr<Reintegration>(new Reintegration(std::move(*engine), from.index));
}

Reintegration::Reintegration(std::unique_ptr<Engine> engine, std::uint64_t begin)
    : engine_(std::move(engine)), begin_(begin), next_(begin) {}

Expected<void> Reintegration::advance(const ScanHistory& history, std::uint64_t until,
                                      const std::atomic<bool>* cancel) {
  while (next_ < until) {
    if (cancel != nullptr && cancel->load()) return {};
    auto scan = history.store().read(next_);
    if (!scan) return std::unexpected(scan.error());
    // A rejected scan changes nothing, here as it did live.
    (void)engine_->integrate(*scan);
    ++next_;
    if (history.hasCheckpointAt(next_)) checkpoints_.push_back({next_, engine_->view()});
  }
  return {};
}

std::size_t Reintegration::patch(OccupancyMap& live, const MapView& live_view,
                                 CellChanges& changes) const {
  const auto rebuilt = engine_->view();
  std::vector<std::uint64_t> blocks;
  live_view.forEachBlock([&](std::uint64_t key, const VoxelBlock&) { blocks.push_back(key); });
  rebuilt->forEachBlock([&](std::uint64_t key, const VoxelBlock&) { blocks.push_back(key); });
  const VersionDelta delta = diffVersions(live_view, *rebuilt, blocks);
  CellChanges cells = delta.changes();
  for (const CellChange& c : cells) {
    if (c.known) {
      live.setLogOdds(c.key, c.log_odds);
    } else {
      live.clearBox(c.key, c.key);
    }
  }
  changes.insert(changes.end(), cells.begin(), cells.end());
  return cells.size();
}

}  // namespace densemap
