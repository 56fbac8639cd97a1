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

namespace densemap::server {

/// A bounded queue where a push into a full queue drops the OLDEST item (counted): when the
/// consumer falls behind, it always gets the freshest data and the backlog never grows.
/// With a key (a sensor id), the latest wins per key: each key has at most `capacity` items
/// waiting and a push drops that key's oldest, so one fast sensor cannot push out another's
/// scans. All keys together hold `total_capacity` items; beyond it the key with the most items
/// waiting gives up its oldest (so every key keeps its latest), and while every waiting key
/// holds one item the queue grows to one item per key, up to `max_keys` keys: only beyond that
/// many keys at once does a key lose its only item (the oldest of all). With a byte budget
/// (`size_of` gives an item's bytes), the items waiting never hold more than `byte_budget`
/// bytes (one item larger than all of it still waits alone): beyond it, the key with the most
/// items waiting gives up its oldest, else the oldest of all goes. Items are taken in arrival
/// order. Thread-safe: any number of producers and consumers.
template <class T>
class LatestWinsQueue {
 public:
  using KeyOf = std::function<const std::string&(const T&)>;
  using SizeOf = std::function<std::size_t(const T&)>;
  explicit LatestWinsQueue(std::size_t capacity, std::size_t total_capacity = 0, KeyOf key = {},
                           std::size_t max_keys = 64, SizeOf size_of = {},
                           std::size_t byte_budget = 0)
      : capacity_(capacity == 0 ? 1 : capacity),
        total_capacity_(std::max(capacity_, total_capacity)),
        max_keys_(max_keys),
        key_(std::move(key)),
        size_of_(std::move(size_of)),
        byte_budget_(size_of_ ? byte_budget : 0) {}

  /// Returns false if the queue was closed (the item is discarded). When the queue (or the
  /// item's key, or the byte budget) was full, the oldest items (of that key) are dropped and,
  /// if `dropped` is given, appended to it.
  bool push(T item, std::vector<T>* dropped = nullptr) {
    {
      std::lock_guard lock(mutex_);
      if (closed_) return false;
      const auto drop = [&](typename std::deque<T>::iterator victim) {
        if (size_of_) bytes_ -= size_of_(*victim);
        if (dropped != nullptr) dropped->push_back(std::move(*victim));
        items_.erase(victim);
        ++dropped_;
      };
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
      if (victim != items_.end()) drop(victim);
      const std::size_t item_bytes = size_of_ ? size_of_(item) : 0;
      while (byte_budget_ > 0 && !items_.empty() && bytes_ + item_bytes > byte_budget_) {
        const Fullest f = fullestKey();
        drop(f.items >= 2 ? f.oldest : items_.begin());
      }
      bytes_ += item_bytes;
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
    if (size_of_) bytes_ -= size_of_(item);
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
      bytes_ = 0;
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
  /// Whether `item` would wait without pushing another item out (its key below `capacity`, the
  /// queue below `total_capacity`, the byte budget not exceeded).
  [[nodiscard]] bool hasRoomFor(const T& item) const {
    std::lock_guard lock(mutex_);
    if (items_.size() >= total_capacity_) return false;
    if (byte_budget_ > 0 && bytes_ + size_of_(item) > byte_budget_ && !items_.empty()) {
      return false;
    }
    if (!key_) return items_.size() < capacity_;
    const std::string& key = key_(item);
    std::size_t same = 0;
    for (const T& waiting : items_) same += key_(waiting) == key ? 1 : 0;
    return same < capacity_;
  }
  /// Bytes the waiting items hold (by `size_of`; 0 without it).
  [[nodiscard]] std::size_t bytes() const {
    std::lock_guard lock(mutex_);
    return bytes_;
  }

 private:
  /// The key with the most items waiting (of those, the one whose oldest came first): its
  /// oldest item and how many it holds, and how many keys have items waiting. Without keys,
  /// the oldest item and the queue's size.
  struct Fullest {
    typename std::deque<T>::iterator oldest;
    std::size_t items = 0;
    std::size_t keys = 0;
  };
  Fullest fullestKey() {
    if (!key_) return {items_.begin(), items_.size(), items_.empty() ? 0U : 1U};
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
    if (counts.empty()) return {items_.end(), 0, 0};
    std::size_t most = 0;
    for (std::size_t i = 1; i < counts.size(); ++i) {
      if (counts[i].second > counts[most].second) most = i;  // ties: the first key seen
    }
    return {oldest[most], counts[most].second, counts.size()};
  }

  /// The queue is at its total: the oldest item of the key with the most items waiting, when
  /// that key holds two or more; else (one item per key) none while the keys, with a
  /// `new_key`, number at most max_keys_; else the oldest.
  typename std::deque<T>::iterator fairVictim(bool new_key) {
    const Fullest f = fullestKey();
    if (f.items == 0) return items_.end();
    if (f.items >= 2) return f.oldest;
    if (f.keys + (new_key ? 1 : 0) <= max_keys_) return items_.end();
    return items_.begin();
  }

  mutable std::mutex mutex_;
  std::condition_variable ready_;
  std::deque<T> items_;
  std::size_t capacity_;
  std::size_t total_capacity_;
  std::size_t max_keys_;
  KeyOf key_;
  SizeOf size_of_;
  std::size_t byte_budget_;
  std::size_t bytes_ = 0;
  std::size_t dropped_ = 0;
  bool closed_ = false;
};

}  // namespace densemap::server
