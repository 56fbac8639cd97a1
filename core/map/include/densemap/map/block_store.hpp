#pragma once

#include <atomic>
#include <cstdint>
#include <deque>
#include <memory>
#include <mutex>
#include <vector>

#include "densemap/map/voxel_block.hpp"

namespace densemap {

/// The contents of one block as one map version wrote them. Nodes of the same block form a
/// chain from newest to oldest, so a reader of an older version finds the contents it saw.
struct BlockNode {
  std::uint64_t version = 0;               // the map version that wrote these contents
  std::atomic<BlockNode*> older{nullptr};  // the contents before; null once nobody reads them
  VoxelBlock voxels;
  block::BlockMask fully_free{};  // known cells at the lower clamping bound
};

/// A block's place in the store: its key and its newest contents.
struct BlockEntry {
  explicit BlockEntry(std::uint64_t block_key) : key(block_key) {}
  const std::uint64_t key;
  std::atomic<BlockNode*> head{nullptr};
};

/// The blocks of a GridMap: ONE copy of the map, readable at every published version while the
/// writer builds the next one (multi-version concurrency per block).
///
/// The writer changes a block of a published version by copying it into a new node (copy on
/// write) and linking the old node behind it; readers of version V walk a block's chain to
/// the newest node with version <= V. A version's superseded nodes go back to the node pool
/// when no reader holds that version or an older one: every published version has a pin, and a
/// pin keeps the next version's pin alive, so the chain unwinds from the oldest reader. So a
/// scan costs O(changed blocks) whatever the map's size, readers never wait for the writer
/// (no locks on the read path) and the writer never waits for readers.
///
/// Until the first publish() the store is unversioned: every write goes in place (the offline
/// tools and benchmarks pay nothing for versioning).
///
/// Block entries are never removed (a cleared block keeps its entry and an empty node). The
/// hash table is open addressing, insert-only: readers probe it without locks while the writer
/// inserts; a grown table replaces the old one, which is kept until the store dies (at most as
/// large as the current one).
///
/// Thread-safety: writer methods from one thread at a time (`writable` may run in parallel
/// tasks on distinct entries); reader methods (`find`, `forEachEntry`, `nodeAt`) from any thread
/// with a version whose pin they hold.
class BlockStore {
 public:
  BlockStore();
  ~BlockStore();
  BlockStore(const BlockStore&) = delete;
  BlockStore& operator=(const BlockStore&) = delete;

  // ---- writer ----
  /// The version that writes go to.
  [[nodiscard]] std::uint64_t writingVersion() const { return writing_; }
  /// The entry of `block_key`, created (with no contents) if missing.
  BlockEntry& entry(std::uint64_t block_key);
  /// The latest contents of a block (the writer's view), or null.
  [[nodiscard]] const BlockNode* latest(std::uint64_t block_key) const;
  /// The node that writes of the current version go to: the head itself when this version
  /// already wrote it (or the store is unversioned), else a copy of the head (or an empty node)
  /// that becomes the new head. Safe from parallel tasks for distinct entries.
  BlockNode& writable(BlockEntry& entry);
  /// Ends the version being written and starts the next one. Returns the pin of the version
  /// just ended (readers hold it) and the blocks that version wrote, in no particular order.
  struct Published {
    std::shared_ptr<const void> pin;
    std::uint64_t version = 0;
    std::vector<std::uint64_t> written_blocks;
  };
  Published publish();
  /// Grows the node pool to at least `nodes` free nodes (allocated and zeroed now, so the
  /// pages are faulted in before they are needed).
  void reserve(std::size_t nodes);
  /// Before the first publish: the version number the current contents belong to.
  void startAt(std::uint64_t version);
  /// Drops every block (only while unversioned, i.e. before the first publish).
  void clearUnversioned();
  /// Calls f(entry) for every entry (writer: its own insertion order).
  template <typename F>
  void forEachEntryWriter(F&& f) const {
    for (const BlockEntry& e : entries_) f(e);
  }
  template <typename F>
  void forEachEntryWriter(F&& f) {
    for (BlockEntry& e : entries_) f(e);
  }
  /// Whether a version was ever published (writes then copy blocks readers may hold).
  [[nodiscard]] bool versioned() const { return versioned_; }

  // ---- readers ----
  /// The contents of `block_key` at `version`, or null when the block had none then.
  [[nodiscard]] const BlockNode* find(std::uint64_t block_key, std::uint64_t version) const;
  [[nodiscard]] static const BlockNode* nodeAt(const BlockEntry& entry, std::uint64_t version);
  /// Calls f(entry) for every entry of the table (entries created after `version` have no node
  /// at it: nodeAt returns null).
  template <typename F>
  void forEachEntry(F&& f) const {
    const Table* t = table_.load(std::memory_order_acquire);
    for (std::size_t i = 0; i <= t->mask; ++i) {
      const BlockEntry* e = t->slots[i].load(std::memory_order_acquire);
      if (e != nullptr) f(*e);
    }
  }

  [[nodiscard]] std::size_t entryCount() const { return entries_.size(); }
  /// Nodes in use (heads + those kept for readers) and bytes held by nodes, pool and table.
  [[nodiscard]] std::size_t liveNodes() const { return live_nodes_.load(); }
  [[nodiscard]] std::size_t memoryBytes() const;

 private:
  struct Table {
    explicit Table(int bits);
    int shift;
    std::size_t mask;
    std::unique_ptr<std::atomic<BlockEntry*>[]> slots;
  };
  struct Pin;
  friend struct Pin;
  [[nodiscard]] static std::size_t slotOf(const Table& t, std::uint64_t key);
  void grow();
  BlockNode* allocate();  // pool_mutex_ held
  void addSlab();         // pool_mutex_ held
  void release(const std::vector<std::pair<BlockNode*, BlockNode*>>& superseded);

  std::uint64_t writing_ = 0;
  bool versioned_ = false;
  std::deque<BlockEntry> entries_;
  std::atomic<Table*> table_;
  std::vector<std::unique_ptr<Table>> tables_;  // the current one last

  mutable std::mutex pool_mutex_;
  std::vector<std::unique_ptr<BlockNode[]>> slabs_;
  std::vector<BlockNode*> free_;
  std::atomic<std::size_t> live_nodes_{0};
  // Of the version being written: (old, new) node pairs and the blocks written.
  std::vector<std::pair<BlockNode*, BlockNode*>> superseded_;
  std::vector<std::uint64_t> written_;
  std::shared_ptr<Pin> current_pin_;  // the last published version's pin
};

}  // namespace densemap
