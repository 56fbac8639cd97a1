#pragma once

#include <algorithm>
#include <chrono>
#include <condition_variable>
#include <cstddef>
#include <deque>
#include <functional>
#include <mutex>
#include <optional>
#include <string>

namespace densemap {

/// A bounded queue where a push into a full queue drops the OLDEST item (counted): when the
/// consumer falls behind, it always gets the freshest data and the backlog never grows.
/// With a key (a sensor id), the latest wins per key: each key has at most `capacity` items
/// waiting and a push drops that key's oldest, so one fast sensor cannot push out another's
/// scans; all keys together have at most `total_capacity`, beyond which the oldest item of any
/// key is dropped. Items are taken in arrival order. Thread-safe: any number of producers and
/// consumers.
template <class T>
class LatestWinsQueue {
 public:
  using KeyOf = std::function<const std::string&(const T&)>;
  explicit LatestWinsQueue(std::size_t capacity, std::size_t total_capacity = 0, KeyOf key = {})
      : capacity_(capacity == 0 ? 1 : capacity),
        total_capacity_(std::max(capacity_, total_capacity)),
        key_(std::move(key)) {}

  /// Returns false if the queue was closed (the item is discarded). When the queue (or the
  /// item's key) was full, the oldest item (of that key) is dropped and, if `dropped` is given,
  /// moved there.
  bool push(T item, std::optional<T>* dropped = nullptr) {
    {
      std::lock_guard lock(mutex_);
      if (closed_) return false;
      auto victim = items_.end();
      if (key_) {
        const std::string& key = key_(item);
        std::size_t same = 0;
        for (auto it = items_.begin(); it != items_.end(); ++it) {
          if (key_(*it) != key) continue;
          if (same++ == 0) victim = it;
        }
        if (same < capacity_) victim = items_.end();
      }
      if (victim == items_.end() && items_.size() >= total_capacity_) victim = items_.begin();
      if (victim != items_.end()) {
        if (dropped != nullptr) *dropped = std::move(*victim);
        items_.erase(victim);
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
  std::size_t total_capacity_;
  KeyOf key_;
  std::size_t dropped_ = 0;
  bool closed_ = false;
};

}  // namespace densemap
