#include "densemap/ros2/tf_buffer.hpp"

#include <algorithm>
#include <cmath>
#include <limits>
#include <vector>

namespace densemap::ros2 {
namespace {

std::string_view stripSlash(std::string_view frame) {
  while (!frame.empty() && frame.front() == '/') frame.remove_prefix(1);
  return frame;
}

Eigen::Isometry3d toIsometry(const Eigen::Vector3d& t, const Eigen::Quaterniond& q) {
  Eigen::Isometry3d T = Eigen::Isometry3d::Identity();
  T.linear() = q.normalized().toRotationMatrix();
  T.translation() = t;
  return T;
}

}  // namespace

bool TfBuffer::set(std::string_view parent_name, std::string_view child_name,
                   const TfSample& sample, bool is_static) {
  const std::string_view parent = stripSlash(parent_name);
  const std::string_view child = stripSlash(child_name);
  if (parent.empty() || child.empty() || parent == child) return false;
  if (!sample.t.allFinite() || !sample.q.coeffs().allFinite()) return false;
  if (std::abs(sample.q.norm() - 1.0) > 1e-3) return false;
  // A cycle: `child` is an ancestor of `parent`.
  for (std::string_view f = parent; !f.empty();) {
    if (f == child) return false;
    const auto it = links_.find(f);
    if (it == links_.end()) break;
    f = it->second.parent;
  }
  Link& link = links_[std::string(child)];
  if (link.parent != parent || link.is_static != is_static) {
    link.parent = std::string(parent);
    link.is_static = is_static;
    link.samples.clear();
  }
  if (is_static) {
    link.samples.assign(1, sample);
    return true;
  }
  // Keep stamps ordered; an equal stamp replaces its sample.
  auto at = std::lower_bound(link.samples.begin(), link.samples.end(), sample.stamp_ns,
                             [](const TfSample& s, std::int64_t t) { return s.stamp_ns < t; });
  if (at != link.samples.end() && at->stamp_ns == sample.stamp_ns) {
    *at = sample;
  } else {
    link.samples.insert(at, sample);
  }
  const std::int64_t oldest = link.samples.back().stamp_ns - cache_ns_;
  while (link.samples.size() > 2 && link.samples.front().stamp_ns < oldest) {
    link.samples.pop_front();
  }
  return true;
}

std::expected<Eigen::Isometry3d, TfFailure> TfBuffer::sampleAt(const Link& link,
                                                               std::int64_t stamp_ns) const {
  const auto& s = link.samples;
  if (link.is_static || s.size() == 1) {
    if (!link.is_static && s.front().stamp_ns != stamp_ns) {
      return std::unexpected(stamp_ns > s.front().stamp_ns ? TfFailure::kNotYet
                                                           : TfFailure::kTooOld);
    }
    return toIsometry(s.front().t, s.front().q);
  }
  if (stamp_ns > s.back().stamp_ns) return std::unexpected(TfFailure::kNotYet);
  if (stamp_ns < s.front().stamp_ns) return std::unexpected(TfFailure::kTooOld);
  auto hi = std::lower_bound(s.begin(), s.end(), stamp_ns,
                             [](const TfSample& a, std::int64_t t) { return a.stamp_ns < t; });
  if (hi->stamp_ns == stamp_ns) return toIsometry(hi->t, hi->q);
  auto lo = hi - 1;
  const double r = static_cast<double>(stamp_ns - lo->stamp_ns) /
                   static_cast<double>(hi->stamp_ns - lo->stamp_ns);
  const Eigen::Vector3d t = lo->t + r * (hi->t - lo->t);
  const Eigen::Quaterniond q = lo->q.normalized().slerp(r, hi->q.normalized());
  return toIsometry(t, q);
}

std::expected<Eigen::Isometry3d, TfFailure> TfBuffer::chain(const std::string& frame,
                                                            const std::string& root,
                                                            std::int64_t stamp_ns) const {
  Eigen::Isometry3d T = Eigen::Isometry3d::Identity();
  for (std::string f = frame; f != root;) {
    const auto it = links_.find(f);
    if (it == links_.end()) return std::unexpected(TfFailure::kNoPath);
    auto step = sampleAt(it->second, stamp_ns);
    if (!step) return std::unexpected(step.error());
    T = *step * T;
    f = it->second.parent;
  }
  return T;
}

std::int64_t TfBuffer::latestCommon(const std::string& a, const std::string& b) const {
  std::int64_t latest = std::numeric_limits<std::int64_t>::max();
  bool moving = false;
  for (const std::string* start : {&a, &b}) {
    for (std::string f = *start;;) {
      const auto it = links_.find(f);
      if (it == links_.end()) break;
      if (!it->second.is_static) {
        latest = std::min(latest, it->second.samples.back().stamp_ns);
        moving = true;
      }
      f = it->second.parent;
    }
  }
  return moving ? latest : 0;
}

std::string TfBuffer::rootOf(std::string_view frame) const {
  std::string f(stripSlash(frame));
  // set() refuses cycles, so the walk ends; the bound is for safety only.
  for (std::size_t step = 0; step <= links_.size(); ++step) {
    const auto it = links_.find(f);
    if (it == links_.end()) break;
    f = it->second.parent;
  }
  return f;
}

std::expected<Eigen::Isometry3d, TfFailure> TfBuffer::lookup(std::string_view target_name,
                                                             std::string_view source_name,
                                                             std::int64_t stamp_ns) const {
  const std::string target(stripSlash(target_name));
  const std::string source(stripSlash(source_name));
  const auto known = [&](const std::string& f) {
    if (links_.contains(f)) return true;
    return std::any_of(links_.begin(), links_.end(),
                       [&](const auto& l) { return l.second.parent == f; });
  };
  if (target == source) {
    if (!known(target)) return std::unexpected(TfFailure::kUnknownFrame);
    return Eigen::Isometry3d::Identity();
  }
  if (!known(target) || !known(source)) return std::unexpected(TfFailure::kUnknownFrame);
  // The common ancestor: the first frame on source's way up that is on target's way up.
  std::vector<std::string> up_target{target};
  for (auto it = links_.find(target); it != links_.end(); it = links_.find(it->second.parent)) {
    up_target.push_back(it->second.parent);
  }
  std::string root;
  for (std::string f = source;;) {
    if (std::find(up_target.begin(), up_target.end(), f) != up_target.end()) {
      root = f;
      break;
    }
    const auto it = links_.find(f);
    if (it == links_.end()) return std::unexpected(TfFailure::kNoPath);
    f = it->second.parent;
  }
  const std::int64_t stamp = stamp_ns == 0 ? latestCommon(target, source) : stamp_ns;
  auto root_source = chain(source, root, stamp);
  if (!root_source) return std::unexpected(root_source.error());
  auto root_target = chain(target, root, stamp);
  if (!root_target) return std::unexpected(root_target.error());
  return root_target->inverse() * *root_source;
}

}  // namespace densemap::ros2
