#pragma once

#include <Eigen/Geometry>

#include <cstdint>
#include <deque>
#include <expected>
#include <map>
#include <string>
#include <string_view>

namespace densemap::ros2 {

/// One transform parent -> child: a point in the child frame maps to `q * p + t` in the parent.
struct TfSample {
  std::int64_t stamp_ns = 0;
  Eigen::Vector3d t = Eigen::Vector3d::Zero();
  Eigen::Quaterniond q = Eigen::Quaterniond::Identity();
};

enum class TfFailure {
  kUnknownFrame,  // a frame no transform names
  kNoPath,        // the frames are in different trees
  kNotYet,        // the stamp is after the newest sample of a moving link: wait
  kTooOld,        // the stamp is before the oldest sample kept: it will never resolve
};

/// tf2's buffer, for one reader: a tree of frames (each child has one parent), moving links
/// kept for `cache_ns` behind their newest sample, static links forever. A lookup at a stamp
/// chains the links through the frames' common ancestor, interpolating each moving link
/// between the two samples around the stamp (translation linearly, rotation by slerp); no
/// extrapolation. Stamp 0 asks for the latest time every moving link on the path has.
/// Thread-safety: one thread at a time.
class TfBuffer {
 public:
  explicit TfBuffer(std::int64_t cache_ns = 10'000'000'000) : cache_ns_(cache_ns) {}

  /// Adds a sample. Rejected (false): empty or equal frame names, a non-finite translation, a
  /// zero or non-unit quaternion (|q| not within 1e-3 of 1), a child that would make a cycle.
  /// A leading '/' of a frame name is ignored. A new parent for a child replaces its link.
  bool set(std::string_view parent, std::string_view child, const TfSample& sample, bool is_static);

  /// The transform taking points in `source` to `target` at `stamp_ns`: T_target_source.
  [[nodiscard]] std::expected<Eigen::Isometry3d, TfFailure> lookup(std::string_view target,
                                                                   std::string_view source,
                                                                   std::int64_t stamp_ns) const;

  [[nodiscard]] std::size_t links() const { return links_.size(); }
  /// The top of `frame`'s tree (the frame itself when nothing is its parent).
  [[nodiscard]] std::string rootOf(std::string_view frame) const;

 private:
  struct Link {
    std::string parent;
    bool is_static = false;
    std::deque<TfSample> samples;  // by stamp, oldest first
  };
  /// T_root_frame along the chain up from `frame` to `root` (exclusive) at `stamp_ns`.
  [[nodiscard]] std::expected<Eigen::Isometry3d, TfFailure> chain(const std::string& frame,
                                                                  const std::string& root,
                                                                  std::int64_t stamp_ns) const;
  [[nodiscard]] std::expected<Eigen::Isometry3d, TfFailure> sampleAt(const Link& link,
                                                                     std::int64_t stamp_ns) const;
  /// The latest stamp at which every moving link between the frames and `root` has a sample.
  [[nodiscard]] std::int64_t latestCommon(const std::string& a, const std::string& b) const;

  std::int64_t cache_ns_;
  std::map<std::string, Link, std::less<>> links_;  // by child frame
};

}  // namespace densemap::ros2
