#pragma once

#include <algorithm>
#include <cstddef>
#include <iterator>
#include <memory>
#include <new>
#include <utility>
#include <vector>

namespace densemap {

/// Append-only storage whose elements never move (the block store's entries: its hash table
/// and region index point at them), in chunks that double from kFirstChunk up to kMaxChunk
/// elements, so that appending allocates once per chunk. (std::deque, which it replaces,
/// allocates every 512 bytes: up to ~60 allocations a scan at 0.1 m while the map grows, each a
/// walk of the allocator's unsorted free chunks when another part of the process has just freed
/// many small ones.)
template <class T, std::size_t kFirstChunk = 64, std::size_t kMaxChunk = 16384>
class StableVector {
  struct Chunk {
    T* items;
    std::size_t used;
    std::size_t capacity;
  };

  template <class Value>
  class Iter {
   public:
    using iterator_category = std::forward_iterator_tag;
    using value_type = T;
    using difference_type = std::ptrdiff_t;
    using pointer = Value*;
    using reference = Value&;
    Iter() = default;
    Iter(const Chunk* chunk, const Chunk* end) : chunk_(chunk), end_(end) { skipEmpty(); }
    reference operator*() const { return chunk_->items[at_]; }
    pointer operator->() const { return chunk_->items + at_; }
    Iter& operator++() {
      if (++at_ == chunk_->used) {
        ++chunk_;
        at_ = 0;
        skipEmpty();
      }
      return *this;
    }
    Iter operator++(int) {
      Iter before = *this;
      ++*this;
      return before;
    }
    friend bool operator==(const Iter& a, const Iter& b) {
      return a.chunk_ == b.chunk_ && a.at_ == b.at_;
    }

   private:
    void skipEmpty() {
      while (chunk_ != end_ && chunk_->used == 0) ++chunk_;
    }
    const Chunk* chunk_ = nullptr;
    const Chunk* end_ = nullptr;
    std::size_t at_ = 0;
  };

 public:
  using iterator = Iter<T>;
  using const_iterator = Iter<const T>;

  StableVector() = default;
  StableVector(const StableVector&) = delete;
  StableVector& operator=(const StableVector&) = delete;
  StableVector(StableVector&& other) noexcept
      : chunks_(std::exchange(other.chunks_, {})), size_(std::exchange(other.size_, 0)) {}
  StableVector& operator=(StableVector&& other) noexcept {
    if (this != &other) {
      release();
      chunks_ = std::exchange(other.chunks_, {});
      size_ = std::exchange(other.size_, 0);
    }
    return *this;
  }
  ~StableVector() { release(); }

  /// Constructs an element at the end; earlier elements stay where they are.
  template <class... Args>
  T& emplace_back(Args&&... args) {
    if (chunks_.empty() || chunks_.back().used == chunks_.back().capacity) addChunk();
    Chunk& c = chunks_.back();
    T* item = ::new (static_cast<void*>(c.items + c.used)) T(std::forward<Args>(args)...);
    ++c.used;
    ++size_;
    return *item;
  }
  [[nodiscard]] std::size_t size() const { return size_; }
  [[nodiscard]] bool empty() const { return size_ == 0; }
  /// Elements' bytes held, used or not.
  [[nodiscard]] std::size_t capacityBytes() const {
    std::size_t n = 0;
    for (const Chunk& c : chunks_) n += c.capacity;
    return n * sizeof(T);
  }
  /// Destroys every element and frees the chunks.
  void clear() { release(); }

  iterator begin() { return {chunks_.data(), chunks_.data() + chunks_.size()}; }
  iterator end() { return {chunks_.data() + chunks_.size(), chunks_.data() + chunks_.size()}; }
  const_iterator begin() const { return {chunks_.data(), chunks_.data() + chunks_.size()}; }
  const_iterator end() const {
    return {chunks_.data() + chunks_.size(), chunks_.data() + chunks_.size()};
  }

 private:
  void addChunk() {
    const std::size_t capacity =
        chunks_.empty() ? kFirstChunk : std::min(kMaxChunk, chunks_.back().capacity * 2);
    chunks_.reserve(chunks_.size() + 1);  // no throw between the allocation and its record
    chunks_.push_back({std::allocator<T>().allocate(capacity), 0, capacity});
  }
  void release() {
    for (Chunk& c : chunks_) {
      std::destroy_n(c.items, c.used);
      std::allocator<T>().deallocate(c.items, c.capacity);
    }
    chunks_.clear();
    size_ = 0;
  }

  std::vector<Chunk> chunks_;
  std::size_t size_ = 0;
};

}  // namespace densemap
