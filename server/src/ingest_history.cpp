// The ingest's map history (IngestOptions::history, docs/fleet.md): scans recorded after
// integration, pose corrections applied on the worker, and the background re-integration that
// is swapped in as one version.
#include <spdlog/spdlog.h>

#include <algorithm>
#include <chrono>

#include "densemap/server/ingest.hpp"
#include "guarded.hpp"
#include "ingest_background.hpp"

namespace densemap::server {

namespace {

/// The background hands over to the worker once it is this close to the live map: the worker
/// then integrates the last scans itself, between live scans.
constexpr std::uint64_t kHandOverScans = 2;
/// Scans the background integrates between progress reports and checks of the store's end.
constexpr std::uint64_t kProgressStep = 8;

}  // namespace

Expected<void> Ingest::refuseCorrection(const std::string& why) {
  std::lock_guard lock(counters_mutex_);
  ++history_status_.corrections;
  ++history_status_.corrections_rejected;
  history_status_.last_error = why;
  return makeError(why);
}

Expected<void> Ingest::correct(PoseCorrection correction) {
  if (!history_)
    return refuseCorrection("pose corrections need the map's history (config history)");
  if (auto ok = checkCorrection(correction, options_.limits); !ok) {
    return refuseCorrection(ok.error().message);
  }
  {
    std::lock_guard lock(corrections_mutex_);
    if (corrections_.size() >= kMaxPendingCorrections) {
      return refuseCorrection("pose correction refused: " + std::to_string(kMaxPendingCorrections) +
                              " corrections wait already");
    }
    corrections_.push_back(std::move(correction));
  }
  std::lock_guard lock(counters_mutex_);
  ++history_status_.corrections;
  return {};
}

void Ingest::historyError(const std::string& message) {
  spdlog::warn("history: {}", message);
  std::lock_guard lock(counters_mutex_);
  history_status_.last_error = message;
}

void Ingest::recordScan(const RawScan& raw) {
  if (!history_) return;
  if (auto ok = history_->record(raw, engine_->view()); !ok) {
    // The history restarted from this version: a re-integration from before it cannot finish.
    cancelReintegration();
    historyError(ok.error().message);
  }
}

void Ingest::restartHistory() {
  if (!history_) return;
  cancelReintegration();
  history_->restart(engine_->view());
}

void Ingest::cancelReintegration() {
  background_.reset();
  std::lock_guard lock(counters_mutex_);
  history_status_.reintegrating = false;
}

void Ingest::applyCorrections() {
  if (!history_) return;
  std::vector<PoseCorrection> pending;
  {
    std::lock_guard lock(corrections_mutex_);
    pending.swap(corrections_);
  }
  std::optional<std::uint64_t> earliest;
  for (const PoseCorrection& c : pending) {
    const CorrectionOutcome outcome = history_->correct(c);
    std::lock_guard lock(counters_mutex_);
    history_status_.corrected_scans += outcome.corrected;
    history_status_.unmatched_poses += outcome.unmatched;
    if (outcome.corrected == 0) {
      ++history_status_.corrections_rejected;
      history_status_.last_error = "a pose correction of '" + c.sensor_id +
                                   "' named no kept scan (" + std::to_string(outcome.unmatched) +
                                   " poses)";
    }
    if (outcome.earliest)
      earliest = std::min(earliest.value_or(*outcome.earliest), *outcome.earliest);
  }
  if (!earliest) return;
  // A re-integration under way started from a checkpoint whose later scans may now have other
  // poses too: one new run from the earlier of the two covers both.
  if (background_) earliest = std::min(*earliest, background_->begin);
  cancelReintegration();
  startReintegration(*earliest);
}

void Ingest::startReintegration(std::uint64_t from_index) {
  const auto from = history_->checkpointBefore(from_index);
  if (!from) {
    historyError("no checkpoint before scan " + std::to_string(from_index));
    return;
  }
  auto bg = std::make_unique<Background>();
  bg->begin = from->index;
  {
    std::lock_guard lock(counters_mutex_);
    history_status_.reintegrating = true;
    history_status_.reintegration_done = 0;
    history_status_.reintegration_total = history_->store().end() - from->index;
  }
  Background* b = bg.get();
  bg->thread = std::thread([this, b, from = *from] {
    try {
      // The copy of the checkpoint's cells is made here, not on the worker: it costs O(map).
      auto re = Reintegration::create(options_, from);
      if (!re) {
        b->error = re.error().message;
        b->ready = true;
        return;
      }
      b->re = std::move(*re);
      while (!b->cancel.load()) {
        const std::uint64_t end = history_->store().end();
        if (b->re->next() + kHandOverScans >= end) break;
        const std::uint64_t until = std::min(end, b->re->next() + kProgressStep);
        Expected<void> ok;
        history_arena_.execute([&] { ok = b->re->advance(*history_, until, &b->cancel); });
        if (!ok) {
          b->error = ok.error().message;
          break;
        }
        std::lock_guard lock(counters_mutex_);
        history_status_.reintegration_done = b->re->next() - b->re->begin();
        history_status_.reintegration_total = history_->store().end() - b->re->begin();
      }
    } catch (...) {
      b->error = "re-integration failed: " + cli::currentFailure();
    }
    b->ready = true;
  });
  background_ = std::move(bg);
}

void Ingest::finishReintegration() {
  if (!background_ || !background_->ready.load()) return;
  background_->thread.join();
  std::unique_ptr<Background> bg = std::move(background_);
  {
    std::lock_guard lock(counters_mutex_);
    history_status_.reintegrating = false;
  }
  if (bg->error) {
    historyError("re-integration abandoned: " + *bg->error);
    return;
  }
  Reintegration& re = *bg->re;
  // The last scans, integrated here so that none arrives between them and the patch.
  Expected<void> caught_up;
  arena_.execute([&] { caught_up = re.advance(*history_, history_->store().end()); });
  if (!caught_up) {
    historyError("re-integration abandoned: " + caught_up.error().message);
    return;
  }
  IntegrationResult result;
  const auto patched = engine_->command(
      [&](OccupancyMap& map, CellChanges& changes) -> Expected<std::string> {
        re.patch(map, *engine_->view(), changes);
        return std::string();
      },
      result);
  if (!patched) {
    historyError("re-integration not swapped in: " + patched.error().message);
    return;
  }
  if (!result.changes.empty()) published(result);
  history_->replaceCheckpoints(re.checkpoints());
  const double ms =
      std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - bg->started)
          .count();
  const std::uint64_t scans = re.next() - re.begin();
  spdlog::info("history: re-integrated {} scans in {:.0f} ms; {} cells changed in version {}",
               scans, ms, result.changes.size(), engine_->view()->version());
  std::lock_guard lock(counters_mutex_);
  ++history_status_.reintegrations;
  history_status_.last_ms_per_scan = scans > 0 ? ms / static_cast<double>(scans) : 0.0;
  history_status_.last_version = engine_->view()->version();
  history_status_.reintegration_done = scans;
  history_status_.reintegration_total = scans;
}

}  // namespace densemap::server
