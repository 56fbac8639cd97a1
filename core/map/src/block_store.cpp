#include "densemap/map/block_store.hpp"

#include <algorithm>
#include <cstdio>
#include <cstdlib>
#include <new>

#include "huge_pages.hpp"

namespace densemap {
namespace {

constexpr int kInitialTableBits = 10;
// Nodes come from slabs of this many (one huge page's worth, 953 nodes), allocated and zeroed
// in one go so the pages are faulted in once and then reused: no allocation or page fault per
// block per scan. On a huge page, the apply's writes all over the map miss the TLB far less
// than on 4 KiB pages.
constexpr std::size_t kSlabNodes = kHugePage / sizeof(BlockNode);

}  // namespace

/// Entries and tables replaced by a compaction, kept for readers that may still probe them.
struct BlockStore::Garbage {
  StableVector<BlockEntry> entries;
  std::vector<std::unique_ptr<Table>> tables;
};

/// Keeps the nodes a version could read until nobody reads it or an older version.
struct BlockStore::Pin {
  explicit Pin(BlockStore* owner) : store(owner) {}
  Pin(const Pin&) = delete;
  Pin& operator=(const Pin&) = delete;
  ~Pin() {
    store->release(superseded);
    // Unwind the chain of newer pins nobody else holds without recursing once per version.
    std::shared_ptr<Pin> next = std::move(newer);
    while (next && next.use_count() == 1) {
      std::shared_ptr<Pin> after = std::move(next->newer);
      next.reset();
      next = std::move(after);
    }
  }

  BlockStore* store;
  // (link, successor): links readable up to this version, superseded by the next one
  // (successor null: the entry's tombstone was retired).
  std::vector<std::pair<ChainLink*, ChainLink*>> superseded;
  std::shared_ptr<Garbage> garbage;
  std::shared_ptr<Pin> newer;
};

BlockStore::Slab::Slab(std::size_t n) : count(n) {
  void* p = mapHugePages(n * sizeof(BlockNode));
  if (p == nullptr) throw std::bad_alloc();
  nodes = static_cast<BlockNode*>(p);
  // Constructing writes every node: the pages are faulted in now, not during a scan.
  for (std::size_t i = 0; i < n; ++i) new (nodes + i) BlockNode();
}

BlockStore::Slab::~Slab() {
  for (std::size_t i = 0; i < count; ++i) nodes[i].~BlockNode();
  unmapHugePages(nodes, count * sizeof(BlockNode));
}

BlockStore::Table::Table(int bits)
    : shift(64 - bits),
      mask((std::size_t{1} << bits) - 1),
      slots(std::make_unique<std::atomic<BlockEntry*>[]>(mask + 1)) {}

BlockStore::BlockStore() {
  tables_.push_back(std::make_unique<Table>(kInitialTableBits));
  table_.store(tables_.back().get(), std::memory_order_release);
}

BlockStore::~BlockStore() {
  // Views hold the store, so no reader is left; the last pin returns its nodes to the pool.
  current_pin_.reset();
}

std::size_t BlockStore::slotOf(const Table& t, std::uint64_t key) {
  return static_cast<std::size_t>((key * 0x9E3779B97F4A7C15ULL) >> t.shift);
}

BlockEntry* BlockStore::lookup(std::uint64_t block_key) const {
  const Table* t = table_.load(std::memory_order_acquire);
  std::size_t i = slotOf(*t, block_key);
  for (BlockEntry* e = t->slots[i].load(std::memory_order_acquire); e != nullptr;
       e = t->slots[i].load(std::memory_order_acquire)) {
    if (e->key == block_key) return e;
    i = (i + 1) & t->mask;
  }
  return nullptr;
}

BlockEntry& BlockStore::entry(std::uint64_t block_key) {
  const Table* t = table_.load(std::memory_order_relaxed);
  std::size_t i = slotOf(*t, block_key);
  for (BlockEntry* e = t->slots[i].load(std::memory_order_relaxed); e != nullptr;
       e = t->slots[i].load(std::memory_order_relaxed)) {
    if (e->key == block_key) return *e;
    i = (i + 1) & t->mask;
  }
  BlockEntry& created = entries_.emplace_back(block_key);
  index(created);
  if (entries_.size() * 2 > t->mask + 1) {
    grow();  // reinserts every entry, the new one included
  } else {
    t->slots[i].store(&created, std::memory_order_release);
  }
  return created;
}

void BlockStore::grow() {
  const Table* old = table_.load(std::memory_order_relaxed);
  auto bigger = std::make_unique<Table>(64 - old->shift + 1);
  for (BlockEntry& e : entries_) {
    std::size_t i = slotOf(*bigger, e.key);
    while (bigger->slots[i].load(std::memory_order_relaxed) != nullptr) i = (i + 1) & bigger->mask;
    bigger->slots[i].store(&e, std::memory_order_relaxed);
  }
  // Readers still probing the old table finish there: it stays alive with the store.
  table_.store(bigger.get(), std::memory_order_release);
  tables_.push_back(std::move(bigger));
}

const BlockNode* BlockStore::latest(std::uint64_t block_key) const {
  return find(block_key, ~std::uint64_t{0});
}

const BlockNode* BlockStore::find(std::uint64_t block_key, std::uint64_t version) const {
  const BlockEntry* e = lookup(block_key);
  return e != nullptr ? nodeAt(*e, version) : nullptr;
}

const BlockNode* BlockStore::nodeAt(const BlockEntry& entry, std::uint64_t version) {
  const ChainLink* n = entry.head.load(std::memory_order_acquire);
  while (n != nullptr && n->version > version) n = n->older.load(std::memory_order_acquire);
  return contents(n);
}

void BlockStore::addSlab() {
  slabs_.push_back(std::make_unique<Slab>(kSlabNodes));
  BlockNode* slab = slabs_.back()->nodes;
  for (std::size_t i = kSlabNodes; i-- > 0;) free_.push_back(slab + i);
}

void BlockStore::reserve(std::size_t nodes) {
  std::lock_guard lock(pool_mutex_);
  reserve_nodes_ = std::max(reserve_nodes_, nodes);
  while (free_.size() < nodes) addSlab();
}

BlockNode* BlockStore::allocate() {
  if (free_.empty()) addSlab();
  BlockNode* n = free_.back();
  free_.pop_back();
  live_nodes_.fetch_add(1, std::memory_order_relaxed);
  return n;
}

ChainLink* BlockStore::allocateTomb() {
  if (free_tombs_.empty()) return &tombs_.emplace_back();
  ChainLink* t = free_tombs_.back();
  free_tombs_.pop_back();
  return t;
}

void BlockStore::recycle(ChainLink* link) {
  if (link->dropped) {
    free_tombs_.push_back(link);
  } else {
    free_.push_back(static_cast<BlockNode*>(link));
    live_nodes_.fetch_sub(1, std::memory_order_relaxed);
  }
}

BlockNode* BlockStore::ownHead(ChainLink* head) const {
  const BlockNode* current = contents(head);
  if (current != nullptr && (!versioned_ || head->version == writing_)) {
    return static_cast<BlockNode*>(head);
  }
  return nullptr;
}

BlockNode& BlockStore::writable(BlockEntry& e) {
  ChainLink* head = e.head.load(std::memory_order_relaxed);
  if (BlockNode* own = ownHead(head)) {
    // Live versions: a node's version is the last version that wrote it.
    if (live_ && own->version != writing_) {
      std::lock_guard lock(pool_mutex_);
      keepBatchRoom(1);
      written_.push_back(e.key);
      own->version = writing_;
    }
    return *own;
  }
  BlockNode* node = nullptr;
  {
    std::lock_guard lock(pool_mutex_);
    if (versioned_ || live_) keepBatchRoom(1);  // first: it may throw before the node is taken
    node = allocate();
    if (versioned_ || live_) written_.push_back(e.key);
    if (versioned_ && head != nullptr) superseded_.emplace_back(head, node);
  }
  return becomeHead(e, head, node);
}

BlockNode& BlockStore::WriteBatch::writable(BlockEntry& e) {
  ChainLink* head = e.head.load(std::memory_order_relaxed);
  if (BlockNode* own = store_.ownHead(head)) {
    if (store_.live_ && own->version != store_.writing_) {
      keepRoomForOne();
      written_.push_back(e.key);
      own->version = store_.writing_;
    }
    return *own;
  }
  if (next_ == nodes_.size()) {
    nodes_.clear();
    next_ = 0;
    std::lock_guard lock(store_.pool_mutex_);
    if (store_.versioned_ || store_.live_) {
      store_.keepBatchRoom(kBatchNodes);  // first: it may throw before any node is taken
      store_.batch_room_ += kBatchNodes;
      room_ += kBatchNodes;
    }
    // nodes_ holds kBatchNodes (reserved): a throw from allocate() leaves the nodes taken so
    // far in nodes_, returned by the destructor.
    for (std::size_t k = 0; k < kBatchNodes; ++k) nodes_.push_back(store_.allocate());
  }
  BlockNode* node = nodes_[next_];  // in the pool's order: the most recently freed first
  if (store_.versioned_ || store_.live_) {
    // Before the node counts as used: a throw here leaves it to go back to the pool.
    keepRoomForOne();
    written_.push_back(e.key);
    if (store_.versioned_ && head != nullptr) superseded_.emplace_back(head, node);
  }
  ++next_;
  return store_.becomeHead(e, head, node);
}

void BlockStore::WriteBatch::keepRoomForOne() {
  // The destructor's merge must not allocate: room in the store's lists for every entry this
  // batch lists, kept kBatchNodes at a time.
  if (written_.size() < room_) return;
  std::lock_guard lock(store_.pool_mutex_);
  store_.keepBatchRoom(kBatchNodes);
  store_.batch_room_ += kBatchNodes;
  room_ += kBatchNodes;
}

BlockStore::WriteBatch::~WriteBatch() {
  if (next_ == nodes_.size() && written_.empty() && superseded_.empty() && room_ == 0) return;
  std::lock_guard lock(store_.pool_mutex_);
  // The unused nodes back in the order they came out (the next one on top); free_ held them
  // before, so it has the room.
  for (std::size_t k = nodes_.size(); k > next_; --k) store_.recycle(nodes_[k - 1]);
  // The entries fit the room the refills kept (a node is used only once its entries are in,
  // and a push comes only while a taken node is unused): these inserts do not allocate,
  // whatever the task threw.
  store_.batch_room_ -= room_;
  store_.written_.insert(store_.written_.end(), written_.begin(), written_.end());
  store_.superseded_.insert(store_.superseded_.end(), superseded_.begin(), superseded_.end());
}

void BlockStore::keepBatchRoom(std::size_t more) {
  const std::size_t room = batch_room_ + more;
  // Doubling, not to the entry: a reserve per refill must not copy the lists each time.
  const auto keep = [room](auto& list) {
    if (list.capacity() - list.size() < room) {
      list.reserve(std::max(list.size() + room, 2 * list.capacity()));
    }
  };
  keep(written_);
  keep(superseded_);
}

BlockNode& BlockStore::becomeHead(BlockEntry& e, ChainLink* head, BlockNode* node) {
  const BlockNode* current = contents(head);
  if (current != nullptr) {
    node->voxels = current->voxels;
    node->fully_free = current->fully_free;
  } else {
    node->voxels = VoxelBlock{};
    node->fully_free = block::BlockMask{};
  }
  node->version = writing_;
  node->dropped = false;
  node->older.store(versioned_ ? head : nullptr, std::memory_order_relaxed);
  e.head.store(node, std::memory_order_release);
  return *node;
}

BlockEvidence& BlockStore::evidence(BlockEntry& e) {
  if (!e.evidence) {
    e.evidence = std::make_unique<BlockEvidence>();
    evidence_blocks_.fetch_add(1, std::memory_order_relaxed);
  }
  return *e.evidence;
}

void BlockStore::dropEvidence(BlockEntry& e) {
  if (!e.evidence) return;
  e.evidence.reset();
  evidence_blocks_.fetch_sub(1, std::memory_order_relaxed);
  if (e.head.load(std::memory_order_relaxed) == nullptr) ++retired_since_compaction_;
}

bool BlockStore::drop(BlockEntry& e) {
  dropEvidence(e);
  ChainLink* head = e.head.load(std::memory_order_relaxed);
  if (contents(head) == nullptr) return false;
  std::lock_guard lock(pool_mutex_);
  if (!versioned_) {  // nobody reads another version: free it now
    if (live_) {
      keepBatchRoom(1);
      written_.push_back(e.key);
    }
    e.head.store(nullptr, std::memory_order_release);
    recycle(head);
    return true;
  }
  keepBatchRoom(1);  // the live batches' room stays whole
  // Readers of older versions walk past the tombstone to the contents they saw.
  ChainLink* tomb = allocateTomb();
  tomb->version = writing_;
  tomb->dropped = true;
  tomb->older.store(head, std::memory_order_relaxed);
  e.head.store(tomb, std::memory_order_release);
  superseded_.emplace_back(head, tomb);
  written_.push_back(e.key);
  pending_tombs_.push_back(e.key);
  return true;
}

void BlockStore::retireTombstones() {
  // A tombstone whose older contents are gone (no reader of an older version is left) is the
  // last link: the entry's head becomes null, the tombstone goes when this version's readers do.
  std::size_t kept = 0;
  for (const std::uint64_t key : pending_tombs_) {
    BlockEntry* e = lookup(key);
    ChainLink* head = e != nullptr ? e->head.load(std::memory_order_relaxed) : nullptr;
    if (head == nullptr || !head->dropped) continue;  // written again since: its chain frees it
    if (head->older.load(std::memory_order_acquire) != nullptr) {
      pending_tombs_[kept++] = key;
      continue;
    }
    e->head.store(nullptr, std::memory_order_release);
    superseded_.emplace_back(head, nullptr);
    ++retired_since_compaction_;
  }
  pending_tombs_.resize(kept);
}

void BlockStore::compactIfWorthIt() {
  if (retired_since_compaction_ < 4096 || retired_since_compaction_ * 4 < entries_.size()) return;
  retired_since_compaction_ = 0;
  std::size_t alive = 0;
  const auto live = [](const BlockEntry& e) {
    return e.head.load(std::memory_order_relaxed) != nullptr || e.evidence != nullptr;
  };
  for (const BlockEntry& e : entries_) alive += live(e) ? 1 : 0;
  if (alive * 4 > entries_.size() * 3) return;  // fewer than a quarter dead: not worth it
  auto garbage = std::make_shared<Garbage>();
  garbage->entries = std::move(entries_);
  garbage->tables = std::move(tables_);
  regions_.clear();
  int bits = kInitialTableBits;
  while ((std::size_t{1} << bits) < alive * 2 + 2) ++bits;
  auto table = std::make_unique<Table>(bits);
  for (BlockEntry& old : garbage->entries) {
    if (!live(old)) continue;
    BlockEntry& e = entries_.emplace_back(old.key);
    e.head.store(old.head.load(std::memory_order_relaxed), std::memory_order_relaxed);
    e.evidence = std::move(old.evidence);  // the writer's alone: readers never look at it
    index(e);
    std::size_t i = slotOf(*table, e.key);
    while (table->slots[i].load(std::memory_order_relaxed) != nullptr) i = (i + 1) & table->mask;
    table->slots[i].store(&e, std::memory_order_relaxed);
  }
  // Readers that load the table from now on find the new entries (release); those probing the
  // old ones hold the last published version's pin (or an older one), which keeps them.
  table_.store(table.get(), std::memory_order_release);
  tables_.push_back(std::move(table));
  if (current_pin_) {
    current_pin_->garbage = std::move(garbage);
  }
  ++compactions_;
}

std::size_t BlockStore::trim() {
  std::lock_guard lock(pool_mutex_);
  if (free_.size() <= reserve_nodes_ + kSlabNodes) return 0;
  // The slab of every free node (slabs sorted by address, free nodes too).
  std::vector<std::pair<BlockNode*, std::size_t>> bases;  // slab start, index in slabs_
  for (std::size_t s = 0; s < slabs_.size(); ++s) bases.emplace_back(slabs_[s]->nodes, s);
  std::sort(bases.begin(), bases.end());
  std::sort(free_.begin(), free_.end());
  std::vector<std::size_t> slab_of(free_.size());
  std::vector<std::size_t> free_in(slabs_.size(), 0);
  for (std::size_t i = 0, b = 0; i < free_.size(); ++i) {
    while (b + 1 < bases.size() && bases[b + 1].first <= free_[i]) ++b;
    slab_of[i] = bases[b].second;
    ++free_in[slab_of[i]];
  }
  // Wholly free slabs go, as long as the reserve stays free.
  std::vector<bool> whole(slabs_.size(), false);
  std::size_t spare = free_.size() - reserve_nodes_;
  for (std::size_t s = 0; s < slabs_.size() && spare >= kSlabNodes; ++s) {
    if (free_in[s] == slabs_[s]->count) {
      whole[s] = true;
      spare -= kSlabNodes;
    }
  }
  std::size_t kept_nodes = 0;
  for (std::size_t i = 0; i < free_.size(); ++i) {
    if (!whole[slab_of[i]]) free_[kept_nodes++] = free_[i];
  }
  free_.resize(kept_nodes);
  free_.shrink_to_fit();
  std::size_t freed = 0, kept_slabs = 0;
  for (std::size_t s = 0; s < slabs_.size(); ++s) {
    if (whole[s]) {
      freed += slabs_[s]->count * sizeof(BlockNode);
    } else {
      slabs_[kept_slabs++] = std::move(slabs_[s]);
    }
  }
  slabs_.resize(kept_slabs);
  return freed;
}

BlockStore::Published BlockStore::publish() {
  if (versioned_) {
    retireTombstones();
    compactIfWorthIt();
  }
  auto pin = std::make_shared<Pin>(this);
  Published out;
  out.version = writing_;
  {
    std::lock_guard lock(pool_mutex_);
    out.written_blocks.swap(written_);
    if (current_pin_) {
      // The superseded nodes were readable up to the previous version: its pin owns them.
      current_pin_->superseded.swap(superseded_);
      current_pin_->newer = pin;
    }
    superseded_.clear();
  }
  // Dropping the previous pin frees its nodes at once when no reader holds it.
  current_pin_ = pin;
  out.pin = std::move(pin);
  versioned_ = true;
  ++writing_;
  // Many free nodes (blocks dropped or cleared): give wholly free slabs back to the OS. The
  // threshold then rises so a fragmented pool is not re-sorted every version.
  std::size_t free_now = 0;
  {
    std::lock_guard lock(pool_mutex_);
    free_now = free_.size();
  }
  if (free_now > std::max(trim_threshold_, reserve_nodes_ + 2 * kSlabNodes)) {
    (void)trim();
    std::lock_guard lock(pool_mutex_);
    trim_threshold_ = free_.size() + 2 * kSlabNodes;
  }
  return out;
}

BlockStore::Published BlockStore::advance() {
  Published out;
  out.version = writing_;
  {
    std::lock_guard lock(pool_mutex_);
    out.written_blocks.swap(written_);
  }
  ++writing_;
  return out;
}

void BlockStore::startAt(std::uint64_t version) {
  if (versioned_) {
    std::fprintf(stderr, "BlockStore::startAt after the first publish\n");
    std::abort();
  }
  writing_ = version;
}

void BlockStore::clearUnversioned() {
  if (versioned_) {
    std::fprintf(stderr, "BlockStore::clearUnversioned on a versioned store\n");
    std::abort();
  }
  std::lock_guard lock(pool_mutex_);
  for (BlockEntry& e : entries_) {
    if (ChainLink* n = e.head.load(std::memory_order_relaxed); n != nullptr) recycle(n);
  }
  tables_.clear();
  tables_.push_back(std::make_unique<Table>(kInitialTableBits));
  table_.store(tables_.back().get(), std::memory_order_release);
  entries_.clear();
  evidence_blocks_.store(0);
  regions_.clear();
}

void BlockStore::release(const std::vector<std::pair<ChainLink*, ChainLink*>>& superseded) {
  if (superseded.empty()) return;
  std::lock_guard lock(pool_mutex_);
  for (auto [link, successor] : superseded) {
    // No reader of a version older than the successor's is left: unlink the link.
    if (successor != nullptr) successor->older.store(nullptr, std::memory_order_release);
    recycle(link);
  }
}

std::size_t BlockStore::memoryBytes() const {
  std::size_t table_bytes = 0;
  for (const auto& t : tables_) table_bytes += (t->mask + 1) * sizeof(void*);
  std::lock_guard lock(pool_mutex_);
  return slabs_.size() * kSlabNodes * sizeof(BlockNode) + table_bytes +
         entryBytes() + indexBytes() + free_.capacity() * sizeof(void*) +
         tombs_.capacityBytes() +
         evidence_blocks_.load(std::memory_order_relaxed) * (sizeof(BlockEvidence) + 16);
}

}  // namespace densemap
