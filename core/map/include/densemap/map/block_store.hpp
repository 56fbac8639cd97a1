#pragma once

#include <algorithm>
#include <atomic>
#include <cstdint>
#include <memory>
#include <mutex>
#include <unordered_map>
#include <vector>

#include "densemap/geometry/block_layout.hpp"
#include "densemap/map/region_index.hpp"
#include "densemap/map/stable_vector.hpp"
#include "densemap/map/voxel_block.hpp"

namespace densemap {

/// One link of a block's chain, newest to oldest: the block's contents as one map version
/// wrote them (a BlockNode), or a tombstone saying the block was dropped at that version.
struct ChainLink {
  std::uint64_t version = 0;               // the map version that wrote this link
  std::atomic<ChainLink*> older{nullptr};  // the link before; null once nobody reads it
  bool dropped = false;                    // a tombstone: no contents from `version` on
};

/// The contents of one block as one map version wrote them.
struct BlockNode : ChainLink {
  VoxelBlock voxels;
  block::BlockMask fully_free{};  // known cells at the lower clamping bound
};

/// A block's place in the store: its key, its newest link, and a dense map's evidence (the
/// writer's alone: readers see the log-odds it publishes, never the evidence itself).
struct BlockEntry {
  explicit BlockEntry(std::uint64_t block_key) : key(block_key) {}
  const std::uint64_t key;
  std::atomic<ChainLink*> head{nullptr};
  std::unique_ptr<BlockEvidence> evidence;
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
/// A dense kernel map keeps its alpha/beta evidence in the entries (evidence(), dropEvidence()):
/// one index for the evidence and the log-odds it publishes, and a block dropped (eviction,
/// reset) loses both. The evidence is not versioned: only the writer reads it (a copy per
/// version would cost 4 KiB more per block a scan touches).
///
/// Until the first publish() the store is unversioned: every write goes in place (the offline
/// tools and benchmarks pay nothing for versioning).
///
/// drop() removes a block from the version being written (eviction, reset, a cleared block):
/// a tombstone link goes on the chain so readers of older versions still find the contents;
/// the contents return to the pool when those readers are gone, and the tombstone a little
/// later. The hash table is open addressing, insert-only: readers probe it without locks while
/// the writer inserts; a grown table replaces the old one. When many entries have no contents
/// left, the writer rebuilds entries and table without them (compaction); the old ones live on
/// with the pin of the last published version, for the readers that may still probe them.
/// Slabs of the node pool that are wholly free beyond the reserve go back to the OS (trim).
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
  /// The latest contents of an entry (writer), or null when it has none (never written, or
  /// dropped).
  [[nodiscard]] static const BlockNode* latest(const BlockEntry& entry) {
    return contents(entry.head.load(std::memory_order_relaxed));
  }
  /// The entry of `block_key` (writer), or null.
  [[nodiscard]] BlockEntry* findEntry(std::uint64_t block_key) { return lookup(block_key); }
  [[nodiscard]] const BlockEntry* findEntry(std::uint64_t block_key) const {
    return lookup(block_key);
  }
  /// Removes the block's contents from the version being written (readers of older versions
  /// keep them), and its evidence. Returns whether it had contents.
  bool drop(BlockEntry& entry);
  /// The entry's evidence, created (all zero) if missing.
  BlockEvidence& evidence(BlockEntry& entry);
  /// Drops the entry's evidence (its contents stay; an entry left with neither is counted for
  /// the next compaction, the table being insert-only).
  void dropEvidence(BlockEntry& entry);
  /// Entries with evidence.
  [[nodiscard]] std::size_t evidenceBlocks() const { return evidence_blocks_.load(); }
  /// The node that writes of the current version go to: the head itself when this version
  /// already wrote it (or the store is unversioned), else a copy of the head (or an empty node)
  /// that becomes the new head. Safe from parallel tasks for distinct entries.
  BlockNode& writable(BlockEntry& entry);
  /// writable() for one task's run of blocks: its nodes come from the pool kBatchNodes at a
  /// time and the version's bookkeeping waits in the batch, so the pool's lock is taken once
  /// per refill and once at the end, not once per block (thousands of times a scan, which
  /// makes the tasks of a 2-thread apply wait on each other).
  /// The destructor hands the bookkeeping to the version and the unused nodes back to the
  /// pool without allocating: each refill first keeps room for its nodes' entries in the
  /// version's lists, so a task that throws (out of memory) unwinds through it without ending
  /// the process. Writer side, like writable(); one batch per task.
  class WriteBatch {
   public:
    explicit WriteBatch(BlockStore& store) : store_(store) { nodes_.reserve(kBatchNodes); }
    ~WriteBatch();
    WriteBatch(const WriteBatch&) = delete;
    WriteBatch& operator=(const WriteBatch&) = delete;
    BlockNode& writable(BlockEntry& entry);

   private:
    /// Keeps room for one more entry of written_ in the store's list (a refill's worth).
    void keepRoomForOne();
    static constexpr std::size_t kBatchNodes = 16;
    BlockStore& store_;
    std::vector<BlockNode*> nodes_;  // taken from the pool; those from next_ on not used yet
    std::size_t next_ = 0;
    std::size_t room_ = 0;  // entries kept for this batch in the version's lists
    std::vector<std::uint64_t> written_;
    std::vector<std::pair<ChainLink*, ChainLink*>> superseded_;
  };
  /// Ends the version being written and starts the next one. Returns the pin of the version
  /// just ended (readers hold it) and the blocks that version wrote, in no particular order.
  struct Published {
    std::shared_ptr<const void> pin;
    std::uint64_t version = 0;
    std::vector<std::uint64_t> written_blocks;
  };
  Published publish();
  /// Live versions, the alternative to publish() for a writer whose readers wait for it (the
  /// in-process Mapper's default): the store stays unversioned (writes in place, no copies),
  /// and advance() ends the version being written all the same: it numbers it and lists the
  /// blocks it wrote or dropped. No pin: a reader reads the latest contents, and only while the
  /// writer is not writing. Call startLive() before the first write, and never publish().
  void startLive() { live_ = true; }
  Published advance();
  /// Grows the node pool to at least `nodes` free nodes (allocated and zeroed now, so the
  /// pages are faulted in before they are needed).
  void reserve(std::size_t nodes);
  /// Before the first publish: the version number the current contents belong to.
  void startAt(std::uint64_t version);
  /// Drops every block (only while unversioned, i.e. before the first publish).
  void clearUnversioned();
  /// Returns wholly free slabs of the node pool beyond the reserve to the OS; the bytes freed.
  std::size_t trim();
  /// Calls f(entry) for every entry (writer: its own insertion order).
  template <typename F>
  void forEachEntryWriter(F&& f) const {
    for (const BlockEntry& e : entries_) f(e);
  }
  template <typename F>
  void forEachEntryWriter(F&& f) {
    for (BlockEntry& e : entries_) f(e);
  }
  /// Calls f(entry) for every entry whose block lies in `box` (writer), region by region: the
  /// cost follows the entries in and near the box (and the box's regions), not the whole map.
  template <typename F>
  void forEachEntryIn(const block::BlockBox& box, F&& f) const {
    regions_.forEachIn(box, f);
  }
  /// Calls f(box, for_each) for every region of 8^3 blocks that holds entries (writer): the
  /// region's box of blocks, and a function that calls its argument with each of the region's
  /// entries (BlockEntry*), so a caller can pass over a whole region at once.
  template <typename F>
  void forEachRegionWriter(F&& f) {
    regions_.forEachRegion(f);
  }
  /// Whether a version was ever published (writes then copy blocks readers may hold).
  [[nodiscard]] bool versioned() const { return versioned_; }

  // ---- readers ----
  /// The contents of `block_key` at `version`, or null when the block had none then.
  [[nodiscard]] const BlockNode* find(std::uint64_t block_key, std::uint64_t version) const;
  [[nodiscard]] static const BlockNode* nodeAt(const BlockEntry& entry, std::uint64_t version);
  /// A link's contents: null for a tombstone or no link.
  [[nodiscard]] static const BlockNode* contents(const ChainLink* link) {
    return link != nullptr && !link->dropped ? static_cast<const BlockNode*>(link) : nullptr;
  }
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
  /// Compactions of the entry table so far (for tests).
  [[nodiscard]] std::size_t compactions() const { return compactions_; }
  [[nodiscard]] std::size_t memoryBytes() const;
  /// Bytes of forEachEntryIn's region index (pages of entry pointers, a hash node per region).
  [[nodiscard]] std::size_t indexBytes() const {
    return regions_.bytes();
  }
  /// Bytes of the entries' storage (its chunks, filled or not).
  [[nodiscard]] std::size_t entryBytes() const { return entries_.capacityBytes(); }

 private:
  struct Table {
    explicit Table(int bits);
    int shift;
    std::size_t mask;
    std::unique_ptr<std::atomic<BlockEntry*>[]> slots;
  };
  /// A slab of nodes mapped from the OS (so a trimmed slab's pages really go back).
  struct Slab {
    explicit Slab(std::size_t n);
    ~Slab();
    Slab(const Slab&) = delete;
    Slab& operator=(const Slab&) = delete;
    BlockNode* nodes = nullptr;
    std::size_t count = 0;
  };
  struct Pin;
  struct Garbage;
  friend struct Pin;
  [[nodiscard]] static std::size_t slotOf(const Table& t, std::uint64_t key);
  [[nodiscard]] BlockEntry* lookup(std::uint64_t block_key) const;
  void grow();
  BlockNode* allocate();          // pool_mutex_ held
  ChainLink* allocateTomb();      // pool_mutex_ held
  void recycle(ChainLink* link);  // pool_mutex_ held
  void addSlab();                 // pool_mutex_ held
  /// Room in written_ and superseded_ for `more` entries beyond the batch_room_ kept for live
  /// batches, so that a batch hands its bookkeeping over without allocating; every push to
  /// them while batches may live comes after it. pool_mutex_ held; throws bad_alloc (nothing
  /// changed) when out of memory.
  void keepBatchRoom(std::size_t more);
  /// writable()'s node for `e` from `node` (taken from the pool): the head's contents copied
  /// (or an empty node), the version set, made the head.
  BlockNode& becomeHead(BlockEntry& e, ChainLink* head, BlockNode* node);
  /// `head` as a node this version may write in place (it wrote it already, or the store is
  /// unversioned), else null.
  [[nodiscard]] BlockNode* ownHead(ChainLink* head) const;
  void release(const std::vector<std::pair<ChainLink*, ChainLink*>>& superseded);
  void retireTombstones();  // writer, in publish()
  void compactIfWorthIt();  // writer, in publish()

  void index(BlockEntry& e) { regions_.add(&e); }

  std::uint64_t writing_ = 0;
  bool versioned_ = false;
  bool live_ = false;  // startLive(): unversioned, but the blocks each version writes are listed
  StableVector<BlockEntry> entries_;
  RegionIndex<BlockEntry> regions_;  // forEachEntryIn's index (writer)
  std::atomic<Table*> table_;
  std::vector<std::unique_ptr<Table>> tables_;  // the current one last

  mutable std::mutex pool_mutex_;
  std::vector<std::unique_ptr<Slab>> slabs_;
  std::vector<BlockNode*> free_;
  StableVector<ChainLink> tombs_;  // tombstone storage
  std::vector<ChainLink*> free_tombs_;
  std::atomic<std::size_t> live_nodes_{0};
  std::atomic<std::size_t> evidence_blocks_{0};
  std::size_t reserve_nodes_ = 0;
  std::size_t trim_threshold_ = 0;  // trim when more nodes than this are free
  // Of the version being written: (old, new) link pairs and the blocks written.
  std::vector<std::pair<ChainLink*, ChainLink*>> superseded_;
  std::vector<std::uint64_t> written_;
  std::size_t batch_room_ = 0;  // entries live batches may still hand over (keepBatchRoom)
  std::vector<std::uint64_t> pending_tombs_;  // dropped blocks whose tombstone is still needed
  std::size_t retired_since_compaction_ = 0;
  std::size_t compactions_ = 0;
  std::shared_ptr<Pin> current_pin_;  // the last published version's pin
};

}  // namespace densemap
