#pragma once

#include <chrono>
#include <condition_variable>
#include <cstddef>
#include <deque>
#include <mutex>
#include <optional>

namespace densemap {

/// A bounded queue where a push into a full queue drops the OLDEST item (counted): when the
/// consumer falls behind, it always gets the freshest data and the backlog never grows.
/// Thread-safe: any number of producers and consumers.
template <class T>
class LatestWinsQueue {
 public:
  explicit LatestWinsQueue(std::size_t capacity) : capacity_(capacity == 0 ? 1 : capacity) {}

  /// Returns false if the queue was closed (the item is discarded). When the queue was full,
  /// the oldest item is dropped and, if `dropped` is given, moved there.
  bool push(T item, std::optional<T>* dropped = nullptr) {
    {
      std::lock_guard lock(mutex_);
      if (closed_) return false;
      if (items_.size() == capacity_) {
        if (dropped != nullptr) *dropped = std::move(items_.front());
        items_.pop_front();
        ++dropped_;
      }
      items_.push_back(std::move(item));
    }
    ready_.notify_one();
    return true;
  }

  /// The oldest remaining item; waits up to `timeout`; nullopt on timeout or when closed and
  /// drained.
  std::optional<T> pop(std::chrono::milliseconds timeout) {
    std::unique_lock lock(mutex_);
    ready_.wait_for(lock, timeout, [this] { return closed_ || !items_.empty(); });
    if (items_.empty()) return std::nullopt;
    T item = std::move(items_.front());
    items_.pop_front();
    return item;
  }

  /// Refuses further pushes; items already queued are discarded, counted as dropped and
  /// returned.
  std::deque<T> close() {
    std::deque<T> discarded;
    {
      std::lock_guard lock(mutex_);
      closed_ = true;
      dropped_ += items_.size();
      discarded.swap(items_);
    }
    ready_.notify_all();
    return discarded;
  }

  [[nodiscard]] std::size_t dropped() const {
    std::lock_guard lock(mutex_);
    return dropped_;
  }
  [[nodiscard]] std::size_t size() const {
    std::lock_guard lock(mutex_);
    return items_.size();
  }

 private:
  mutable std::mutex mutex_;
  std::condition_variable ready_;
  std::deque<T> items_;
  std::size_t capacity_;
  std::size_t dropped_ = 0;
  bool closed_ = false;
};

}  // namespace densemap
