#pragma once

#include <cstdint>
#include <optional>

#include "densemap/geometry/block_layout.hpp"
#include "densemap/query/map_view.hpp"

namespace densemap {

/// Cells of one MapView version, keeping the last block found (as Bonxai's Accessor): nearby
/// keys mostly share a block, so a walk over neighbouring cells (a ray, a chunk of query
/// points) looks each block up once. One per thread (it is not thread-safe); valid while the
/// view is.
class BlockAccessor {
 public:
  explicit BlockAccessor(const MapView& view) : view_(view) {}

  /// The cell's log-odds, or std::nullopt where it is unknown (MapView::logOdds).
  [[nodiscard]] std::optional<float> logOdds(const VoxelKey& key) {
    const std::uint64_t b = block::blockOf(key);
    if (b != key_) {
      key_ = b;
      block_ = view_.block(b);
    }
    const int i = block::indexOf(key);
    if (block_ == nullptr || !block_->isKnown(i)) return std::nullopt;
    return block_->log_odds[i];
  }

 private:
  const MapView& view_;
  std::uint64_t key_ = ~std::uint64_t{0};
  const VoxelBlock* block_ = nullptr;
};

}  // namespace densemap
