#pragma once

#include <dds/dds.h>

#include <algorithm>
#include <chrono>
#include <cstdint>
#include <functional>
#include <optional>
#include <span>
#include <string>
#include <string_view>
#include <utility>
#include <vector>

#include "densemap/geometry/error.hpp"
#include "densemap/wire/security.hpp"

namespace densemap::dds {

/// The one place Cyclone return codes become densemap errors.
[[nodiscard]] Expected<void> check(dds_return_t rc, std::string_view what);
[[nodiscard]] Expected<dds_entity_t> checkEntity(dds_entity_t e, std::string_view what);

/// Owns one Cyclone entity (participant, topic, reader, writer, waitset, condition) and deletes
/// it, with its children, when destroyed. Move-only.
class Entity {
 public:
  Entity() = default;
  explicit Entity(dds_entity_t e) : e_(e) {}
  ~Entity() { reset(); }
  Entity(Entity&& o) noexcept : e_(std::exchange(o.e_, 0)) {}
  Entity& operator=(Entity&& o) noexcept {
    if (this != &o) {
      reset();
      e_ = std::exchange(o.e_, 0);
    }
    return *this;
  }
  Entity(const Entity&) = delete;
  Entity& operator=(const Entity&) = delete;
  [[nodiscard]] dds_entity_t get() const { return e_; }
  void reset() {
    if (e_ > 0) dds_delete(e_);
    e_ = 0;
  }

 private:
  dds_entity_t e_ = 0;
};

/// Cyclone configuration for one interface. On loopback (docs/security.md): no
/// multicast, unicast discovery to localhost. On any other interface: Cyclone's default
/// multicast discovery there. Large receive buffers for big scans either way.
[[nodiscard]] std::string domainConfig(const std::string& interface_name);

struct ParticipantOptions {
  std::uint32_t domain_id = 0;
  std::string network_interface = "lo";
  /// DDS Security (authentication, access control, encryption); none: plain DDS.
  std::optional<SecurityFiles> security;
};

/// A participant. When CYCLONEDDS_URI is unset the domain is first created with
/// domainConfig(network_interface), so nothing leaves the machine unless a user asks for it.
/// With `security`, the participant loads Cyclone's built-in security plugins with those files;
/// a process can hold one security identity per domain (a second is refused: Cyclone 0.10
/// checks every local participant of a domain against the first one's permissions).
[[nodiscard]] Expected<Entity> createParticipant(const ParticipantOptions& options);

/// Whether an error from this module is DDS Security refusing an entity (a topic, reader or
/// writer this identity's permissions do not grant).
[[nodiscard]] bool isNotAllowedBySecurity(const Error& error);

struct QosSpec {
  bool reliable = true;
  int depth = 1;  // keep-last depth (0: keep-all)
  bool transient_local = false;
  std::string_view partition{};  // empty: the default partition
  /// Offer XCDR1 only (ROS 2's topics: rmw_cyclonedds offers no XCDR2); else Cyclone's default.
  bool xcdr1_only = false;
};

[[nodiscard]] Expected<Entity> createTopic(const Entity& participant,
                                           const dds_topic_descriptor_t& descriptor,
                                           const std::string& name);
[[nodiscard]] Expected<Entity> createReader(const Entity& participant, const Entity& topic,
                                            const QosSpec& qos);
[[nodiscard]] Expected<Entity> createWriter(const Entity& participant, const Entity& topic,
                                            const QosSpec& qos);

/// Samples a reader lent out (dds_take / dds_read), returned when this goes: a callback that
/// throws does not leak them.
class Loan {
 public:
  Loan(const Entity& reader, void** samples, dds_return_t n)
      : reader_(reader), samples_(samples), n_(n) {}
  ~Loan() { dds_return_loan(reader_.get(), samples_, n_); }
  Loan(const Loan&) = delete;
  Loan& operator=(const Loan&) = delete;

 private:
  const Entity& reader_;
  void** samples_;
  dds_return_t n_;
};

/// Calls `f` on every available valid sample of type T in `reader` (loaned, returned right
/// after `f` runs); `take` removes them from the reader, otherwise they stay (read).
/// Returns how many there were.
template <class T>
std::size_t forEachSample(const Entity& reader, bool take, const std::function<void(const T&)>& f) {
  // A read must see every sample at once (it does not advance); a take can go in batches.
  const std::size_t batch = take ? 256 : 65536;
  std::vector<void*> samples(batch);
  std::vector<dds_sample_info_t> infos(batch);
  std::size_t taken = 0;
  while (true) {
    std::fill(samples.begin(), samples.end(), nullptr);
    const auto max = static_cast<std::uint32_t>(batch);
    const dds_return_t n = take ? dds_take(reader.get(), samples.data(), infos.data(), max, max)
                                : dds_read(reader.get(), samples.data(), infos.data(), max, max);
    if (n <= 0) break;
    {
      const Loan loan(reader, samples.data(), n);
      for (dds_return_t i = 0; i < n; ++i) {
        if (infos[i].valid_data) {
          f(*static_cast<const T*>(samples[i]));
          ++taken;
        }
      }
    }
    if (static_cast<std::size_t>(n) < batch || !take) break;
  }
  return taken;
}

template <class T>
std::size_t takeAll(const Entity& reader, const std::function<void(const T&)>& f) {
  return forEachSample<T>(reader, true, f);
}

/// Takes at most one sample and calls `f` on it when it is valid data. Returns whether a
/// sample (valid or not) was taken.
template <class T, class F>
bool takeOne(const Entity& reader, F&& f) {
  void* sample = nullptr;
  dds_sample_info_t info;
  if (dds_take(reader.get(), &sample, &info, 1, 1) <= 0) return false;
  const Loan loan(reader, &sample, 1);
  if (info.valid_data) f(*static_cast<const T*>(sample));
  return true;
}

/// As takeOne, with the sample's info (who wrote it: info.publication_handle).
template <class T, class F>
bool takeOneWithInfo(const Entity& reader, F&& f) {
  void* sample = nullptr;
  dds_sample_info_t info;
  if (dds_take(reader.get(), &sample, &info, 1, 1) <= 0) return false;
  const Loan loan(reader, &sample, 1);
  if (info.valid_data) f(*static_cast<const T*>(sample), info);
  return true;
}

/// The participant of the writer that wrote a sample `reader` received (its publication
/// handle from the sample info), or nothing if that writer is no longer matched.
[[nodiscard]] std::optional<dds_guid_t> participantOfWriter(const Entity& reader,
                                                            dds_instance_handle_t publication);

/// Waits until `writer` has matched a reader of `participant` (a reply written earlier could
/// be lost: discovery is not symmetric, a client may have matched the server's reply writer
/// before the server has matched the client's reply reader). False after `timeout`.
[[nodiscard]] bool waitForReaderOf(const Entity& writer, const dds_guid_t& participant,
                                   std::chrono::milliseconds timeout);

[[nodiscard]] inline Expected<void> write(const Entity& writer, const void* sample) {
  return check(dds_write(writer.get(), sample), "dds_write");
}

/// A string of a received sample (IDL strings may arrive as null): empty for null.
[[nodiscard]] inline std::string text(const char* s) { return s != nullptr ? s : ""; }

/// Wraps a vector's storage as a Cyclone sequence for writing (no copy; `v` must outlive it).
template <class Seq, class V>
Seq borrowSequence(V& v) {
  Seq s{};
  s._maximum = static_cast<std::uint32_t>(v.size());
  s._length = static_cast<std::uint32_t>(v.size());
  s._buffer = v.data();
  s._release = false;
  return s;
}
/// The same for a read-only span: lent for a write (DDS serialises it and never writes through
/// the buffer).
template <class Seq, class T>
Seq borrowSequence(std::span<const T> v) {
  Seq s{};
  s._maximum = static_cast<std::uint32_t>(v.size());
  s._length = static_cast<std::uint32_t>(v.size());
  s._buffer = const_cast<T*>(v.data());
  s._release = false;
  return s;
}

/// A waitset with a guard condition to wake it for shutdown.
class WaitSet {
 public:
  static Expected<WaitSet> create(const Entity& participant);
  /// Wakes the waitset when `reader` has data; `tag` is returned by wait().
  Expected<void> attachReader(const Entity& reader, dds_attach_t tag);
  /// Blocks up to `timeout`; returns the tags that fired (empty on timeout).
  std::vector<dds_attach_t> wait(std::chrono::milliseconds timeout);
  void wake() { dds_set_guardcondition(guard_.get(), true); }

 private:
  Entity waitset_;
  Entity guard_;
  std::vector<Entity> conditions_;
};

}  // namespace densemap::dds
