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
#include <utility>
#include <vector>

namespace densemap {

/// A bounded queue where a push into a full queue drops the OLDEST item (counted): when the
/// consumer falls behind, it always gets the freshest data and the backlog never grows.
/// With a key (a sensor id), the latest wins per key: each key has at most `capacity` items
/// waiting and a push drops that key's oldest, so one fast sensor cannot push out another's
/// scans. All keys together hold `total_capacity` items; beyond it the key with the most items
/// waiting gives up its oldest (so every key keeps its latest), and while every waiting key
/// holds one item the queue grows to one item per key, up to `max_keys` keys: only beyond that
/// many keys at once does a key lose its only item (the oldest of all). Items are taken in
/// arrival order. Thread-safe: any number of producers and consumers.
template <class T>
class LatestWinsQueue {
 public:
  using KeyOf = std::function<const std::string&(const T&)>;
  explicit LatestWinsQueue(std::size_t capacity, std::size_t total_capacity = 0, KeyOf key = {},
                           std::size_t max_keys = 64)
      : capacity_(capacity == 0 ? 1 : capacity),
        total_capacity_(std::max(capacity_, total_capacity)),
        max_keys_(max_keys),
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
        if (victim == items_.end() && items_.size() >= total_capacity_) {
          victim = fairVictim(same == 0);
        }
      } else if (items_.size() >= total_capacity_) {
        victim = items_.begin();
      }
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
  /// The queue is at its total: the oldest item of the key with the most items waiting (of
  /// those, the one whose oldest came first), when that key holds two or more; else (one item
  /// per key) none while the keys, with a `new_key`, number at most max_keys_; else the oldest.
  typename std::deque<T>::iterator fairVictim(bool new_key) {
    std::vector<std::pair<const std::string*, std::size_t>> counts;  // key, items (few keys)
    std::vector<typename std::deque<T>::iterator> oldest;
    for (auto it = items_.begin(); it != items_.end(); ++it) {
      const std::string& k = key_(*it);
      auto found =
          std::find_if(counts.begin(), counts.end(), [&](const auto& c) { return *c.first == k; });
      if (found == counts.end()) {
        counts.emplace_back(&k, 1);
        oldest.push_back(it);
      } else {
        ++found->second;
      }
    }
    std::size_t most = 0;
    for (std::size_t i = 1; i < counts.size(); ++i) {
      if (counts[i].second > counts[most].second) most = i;  // ties: the first key seen
    }
    if (counts.empty()) return items_.end();
    if (counts[most].second >= 2) return oldest[most];
    if (counts.size() + (new_key ? 1 : 0) <= max_keys_) return items_.end();
    return items_.begin();
  }

  mutable std::mutex mutex_;
  std::condition_variable ready_;
  std::deque<T> items_;
  std::size_t capacity_;
  std::size_t total_capacity_;
  std::size_t max_keys_;
  KeyOf key_;
  std::size_t dropped_ = 0;
  bool closed_ = false;
};

}  // namespace densemap
