// DenseMarks::markQueued and markQueuedBack: the queued walks' steps, one walk at a time (the
// scalar reference), or several side by side in SIMD lanes (walk_lanes.hpp: the same marks).
#include "walk_lanes.hpp"

namespace densemap {

using namespace walks;

namespace {

/// Steps on a queued walk's place (as DenseMarks::Cursor::move), marking each voxel — unless
/// `culled` holds it, which stops the walk — with the blocks entered listed for the first-touch
/// bookkeeping afterwards.
struct PlaceSteps {
  std::uint64_t* words;
  const std::uint64_t* culled;  // null: none
  std::uint32_t* entered;
  std::size_t n_entered = 0;
  std::size_t marked = 0;
  DenseMarks::WalkPlace at;
  template <int A>
  [[gnu::always_inline]] bool step() {
    if (--at.left[A] == 0) {
      at.left[A] = block::kEdge;
      at.addr += static_cast<std::uint64_t>(static_cast<std::int64_t>(at.wrap[A]));
      entered[n_entered++] = static_cast<std::uint32_t>(at.addr >> 9);
    } else {
      at.addr += static_cast<std::uint64_t>(static_cast<std::int64_t>(at.small[A]));
    }
    const std::uint64_t bit = std::uint64_t{1} << (at.addr & 63U);
    if (culled != nullptr && (culled[at.addr >> 6] & bit) != 0) return false;
    words[at.addr >> 6] |= bit;
    ++marked;
    return true;
  }
};

}  // namespace

bool DenseMarks::hasWideWalks() { return hasWideLanes(); }
bool DenseMarks::hasFourWalks() { return hasFourLanes(); }

// The first-touch bookkeeping of this loop (touchIn) kept in locals: seen_'s byte stores may
// alias any member, which would reload the count and the arrays' pointers after each store.
void DenseMarks::finishQueued(std::size_t n_pend, std::size_t n_entered) {
  std::uint64_t* const words = masks_[0].data();
  const std::uint64_t* const pend_w = pend_w_.data();
  const std::uint64_t* const pend_b = pend_b_.data();
  for (std::size_t i = 0; i < n_pend; ++i) words[pend_w[i]] |= pend_b[i];
  std::uint8_t* const seen = seen_.data();
  std::uint32_t* const touched = touched_.data();
  const std::uint32_t* const entered = entered_.data();
  std::size_t count = touched_count_;
  for (std::size_t i = 0; i < n_entered; ++i) touchIn(entered[i], seen, touched, count);
  touched_count_ = count;
}

void DenseMarks::finishPended(std::size_t n_pend) {
  std::uint64_t* const words = masks_[0].data();
  const std::uint64_t* const pend_w = pend_w_.data();
  const std::uint64_t* const pend_b = pend_b_.data();
  std::uint8_t* const seen = seen_.data();
  for (std::size_t i = 0; i < n_pend; ++i) {
    const std::uint64_t w = pend_w[i];
    words[w] |= pend_b[i];
    seen[w / block::kMaskWords] = 1;  // listed later (unlisted_)
  }
  if (n_pend != 0) unlisted_ = true;
}

void DenseMarks::finishPended32(std::size_t n_pend) {
  // The masks' 64-bit words read as pairs of 32-bit ones (little-endian: the low half first).
  using Word32 [[gnu::may_alias]] = std::uint32_t;
  auto* const words = reinterpret_cast<Word32*>(masks_[0].data());
  const std::uint32_t* const pend_w = pend32_w_.data();
  const std::uint32_t* const pend_b = pend32_b_.data();
  std::uint8_t* const seen = seen_.data();
  constexpr unsigned kWords32 = block::kVoxels / 32;
  for (std::size_t i = 0; i < n_pend; ++i) {
    const std::uint32_t w = pend_w[i];
    words[w] |= pend_b[i];
    seen[w / kWords32] = 1;  // listed later (unlisted_)
  }
  if (n_pend != 0) unlisted_ = true;
}

void DenseMarks::markQueued(WalkKernel kernel) {
  const std::size_t n = queue_.size();
  if (n == 0) return;
  std::uint64_t* words = masks_[0].data();
  std::size_t steps = 0;
  for (const QueuedWalk& w : queue_) steps += static_cast<std::size_t>(w.steps) + 1;
  makeRoom(steps, entered_, pend_w_, pend_b_);
  std::size_t n_entered = 0;
#ifdef DENSEMAP_WIDE_WALKS
  if (queuesFixed(kernel)) {
    markQueuedFixed(kernel);
    return;
  }
  if (kernel == WalkKernel::kFour && hasFourWalks()) {
    WideOut out{entered_.data(), pend_w_.data(), pend_b_.data()};
    walkFour(queue_.data(), n, out);
    finishPended(out.n_pend);
    queue_.clear();
    return;
  }
#endif
  (void)kernel;
  for (const QueuedWalk& w : queue_) {
    TraversalStart s;
    for (int a = 0; a < 3; ++a) {
      s.t_max[a] = w.t_max[a];
      s.t_delta[a] = w.t_delta[a];
    }
    PlaceSteps place{words, nullptr, entered_.data() + n_entered, 0, 0, w.at};
    countedSteps(s, w.steps + 1, place);
    n_entered += place.n_entered;
  }
  finishQueued(0, n_entered);
  queue_.clear();
}

DenseMarks::BackWalkCounts DenseMarks::markQueuedBack(const block::BlockMask* culled,
                                                      std::vector<std::uint32_t>& handed_over,
                                                      WalkKernel kernel) {
  BackWalkCounts counts;
  const std::size_t n = back_queue_.size();
  if (n == 0) return counts;
  std::uint64_t* words = masks_[0].data();
  const std::uint64_t* culled_words = culled[0].data();
  std::size_t steps = 0;
  for (const QueuedBackWalk& w : back_queue_) steps += static_cast<std::size_t>(w.total) + 1;
  makeRoom(steps, entered_, pend_w_, pend_b_);
  std::size_t n_entered = 0;
#ifdef DENSEMAP_WIDE_WALKS
  if (queuesFixed(kernel)) {
    counts = markQueuedBackFixed(culled, handed_over, kernel);
    back_queue_.clear();
    return counts;
  }
  if (kernel == WalkKernel::kFour && hasFourWalks()) {
    WideOut out{entered_.data(), pend_w_.data(), pend_b_.data()};
    counts = walkFourBack(back_queue_.data(), n, culled_words, out, handed_over);
    finishPended(out.n_pend);
    back_queue_.clear();
    return counts;
  }
#endif
  (void)kernel;
  for (const QueuedBackWalk& w : back_queue_) {
    BackwardWalk walk;
    for (int a = 0; a < 3; ++a) {
      walk.s.t_delta[a] = w.t_delta[a];
      walk.head[a] = w.head[a];
      walk.next[a] = w.next[a];
    }
    walk.bound = w.bound;
    walk.total = static_cast<std::size_t>(w.total);
    PlaceSteps place{words, culled_words, entered_.data() + n_entered, 0, 0, w.at};
    bool handover = false;
    detail::backwardSteps(walk, place, handover);
    n_entered += place.n_entered;
    if (handover) {
      handed_over.push_back(w.id);
    } else {
      counts.visits += place.marked;
      counts.culled += walk.total - place.marked;
    }
  }
  finishQueued(0, n_entered);
  back_queue_.clear();
  return counts;
}

}  // namespace densemap
