#include "densemap/map/block_store.hpp"

#include <cstdio>
#include <cstdlib>

namespace densemap {
namespace {

constexpr int kInitialTableBits = 10;
// Nodes come from slabs of this many (about 560 KB), allocated and zeroed in one go so the
// pages are faulted in once and then reused: no allocation or page fault per block per scan.
constexpr std::size_t kSlabNodes = 256;

}  // namespace

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
  // (node, successor): nodes readable up to this version, superseded by the next one.
  std::vector<std::pair<BlockNode*, BlockNode*>> superseded;
  std::shared_ptr<Pin> newer;
};

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

BlockEntry& BlockStore::entry(std::uint64_t block_key) {
  const Table* t = table_.load(std::memory_order_relaxed);
  std::size_t i = slotOf(*t, block_key);
  for (BlockEntry* e = t->slots[i].load(std::memory_order_relaxed); e != nullptr;
       e = t->slots[i].load(std::memory_order_relaxed)) {
    if (e->key == block_key) return *e;
    i = (i + 1) & t->mask;
  }
  BlockEntry& created = entries_.emplace_back(block_key);
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
  const Table* t = table_.load(std::memory_order_acquire);
  std::size_t i = slotOf(*t, block_key);
  for (const BlockEntry* e = t->slots[i].load(std::memory_order_acquire); e != nullptr;
       e = t->slots[i].load(std::memory_order_acquire)) {
    if (e->key == block_key) return nodeAt(*e, version);
    i = (i + 1) & t->mask;
  }
  return nullptr;
}

const BlockNode* BlockStore::nodeAt(const BlockEntry& entry, std::uint64_t version) {
  const BlockNode* n = entry.head.load(std::memory_order_acquire);
  while (n != nullptr && n->version > version) n = n->older.load(std::memory_order_acquire);
  return n;
}

void BlockStore::addSlab() {
  slabs_.emplace_back(new BlockNode[kSlabNodes]);
  BlockNode* slab = slabs_.back().get();
  for (std::size_t i = kSlabNodes; i-- > 0;) free_.push_back(slab + i);
}

void BlockStore::reserve(std::size_t nodes) {
  std::lock_guard lock(pool_mutex_);
  while (free_.size() < nodes) addSlab();
}

BlockNode* BlockStore::allocate() {
  if (free_.empty()) addSlab();
  BlockNode* n = free_.back();
  free_.pop_back();
  live_nodes_.fetch_add(1, std::memory_order_relaxed);
  return n;
}

BlockNode& BlockStore::writable(BlockEntry& e) {
  BlockNode* head = e.head.load(std::memory_order_relaxed);
  if (head != nullptr && (!versioned_ || head->version == writing_)) return *head;
  BlockNode* node = nullptr;
  {
    std::lock_guard lock(pool_mutex_);
    node = allocate();
    if (versioned_) {
      written_.push_back(e.key);
      if (head != nullptr) superseded_.emplace_back(head, node);
    }
  }
  if (head != nullptr) {
    node->voxels = head->voxels;
    node->fully_free = head->fully_free;
  } else {
    node->voxels = VoxelBlock{};
    node->fully_free = block::BlockMask{};
  }
  node->version = writing_;
  node->older.store(versioned_ ? head : nullptr, std::memory_order_relaxed);
  e.head.store(node, std::memory_order_release);
  return *node;
}

BlockStore::Published BlockStore::publish() {
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
    if (BlockNode* n = e.head.load(std::memory_order_relaxed); n != nullptr) {
      free_.push_back(n);
      live_nodes_.fetch_sub(1, std::memory_order_relaxed);
    }
  }
  tables_.clear();
  tables_.push_back(std::make_unique<Table>(kInitialTableBits));
  table_.store(tables_.back().get(), std::memory_order_release);
  entries_.clear();
}

void BlockStore::release(const std::vector<std::pair<BlockNode*, BlockNode*>>& superseded) {
  if (superseded.empty()) return;
  std::lock_guard lock(pool_mutex_);
  for (auto [node, successor] : superseded) {
    // No reader of a version older than the successor's is left: unlink the node.
    successor->older.store(nullptr, std::memory_order_release);
    free_.push_back(node);
  }
  live_nodes_.fetch_sub(superseded.size(), std::memory_order_relaxed);
}

std::size_t BlockStore::memoryBytes() const {
  std::size_t table_bytes = 0;
  for (const auto& t : tables_) table_bytes += (t->mask + 1) * sizeof(void*);
  std::lock_guard lock(pool_mutex_);
  return slabs_.size() * kSlabNodes * sizeof(BlockNode) + table_bytes +
         entries_.size() * sizeof(BlockEntry) + free_.capacity() * sizeof(void*);
}

}  // namespace densemap
