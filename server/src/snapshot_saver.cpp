#include "snapshot_saver.hpp"

#include <malloc.h>

#include "densemap/store/snapshot.hpp"

namespace densemap::server {

ReturnFreeMemory::~ReturnFreeMemory() { malloc_trim(0); }

Expected<std::size_t> SnapshotSaver::save(const std::filesystem::path& file) {
  auto saved = saveUncounted(file);
  if (!saved) {
    ++failures_;
    std::lock_guard lock(error_mutex_);
    last_error_ = saved.error().message;
  }
  return saved;
}

std::string SnapshotSaver::lastError() const {
  std::lock_guard lock(error_mutex_);
  return last_error_;
}

Expected<std::size_t> SnapshotSaver::saveUncounted(const std::filesystem::path& file) {
  const std::filesystem::path target = file.empty() ? path_ : file;
  if (target.empty()) return makeError("no snapshot path configured or given");
  const ReturnFreeMemory trim;  // the snapshot's buffers (about the file's size)
  const SensorModel model(ingest_.options().sensor);
  if (file.empty() || file == path_) {
    // One rotation at a time: a command's save and an autosave must not rotate generations
    // under each other.
    const std::lock_guard lock(save_mutex_);
    const Ingest::SavedState state = ingest_.savedState();
    return saveSnapshotKeeping(*state.view, model, ingest_.options().backend, target, keep_,
                               state.kernel ? &*state.kernel : nullptr);
  }
  const Ingest::SavedState state = ingest_.savedState();
  return saveSnapshot(*state.view, model, ingest_.options().backend, target,
                      state.kernel ? &*state.kernel : nullptr);
}

}  // namespace densemap::server
