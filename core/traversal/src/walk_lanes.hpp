#pragma once

// The walk kernels behind DenseMarks::markQueued and markQueuedBack, one file per instruction
// set: walks_four.cpp (AVX2, double times), walks_eight_fixed.cpp (AVX2, 32-bit fixed-point
// times), walks_sixteen_fixed.cpp (AVX-512, fixed point). dense_walks.cpp chooses (the scalar
// walks are the reference); fixed_walks.cpp converts queued walks to fixed point. Every kernel
// makes the same decisions from the same arithmetic as the scalar walk: the same marks.
#include <algorithm>
#include <bit>
#include <cstddef>
#include <cstring>
#include <limits>
#include <vector>

#include "densemap/traversal/backward_traversal.hpp"
#include "densemap/traversal/dense_marks.hpp"
#include "densemap/traversal/ray_traversal.hpp"

#if defined(__x86_64__) && defined(__GNUC__)
#include <immintrin.h>
#define DENSEMAP_WIDE_WALKS 1
#endif

namespace densemap {

/// Buffers of a wide walk: blocks entered, and marks gathered per lane and word, pended when the
/// lane moves to another word (the word's ORs one after the other would wait on each other).
struct WideOut {
  std::uint32_t* entered;
  std::uint64_t* pend_w;
  std::uint64_t* pend_b;
  std::size_t n_entered = 0;
  std::size_t n_pend = 0;
};

/// The 32-bit lanes a mask names, packed to the front (a permute's indices), per 8-bit mask.
/// And per lane, all-ones in the 32-bit lanes but that one.
struct EightLaneTable {
  alignas(32) std::int32_t pack32[256][8];
  alignas(32) std::int32_t others[8][8];
};
constexpr EightLaneTable makeEightLaneTable() {
  EightLaneTable t{};
  for (int m = 0; m < 256; ++m) {
    int n = 0;
    for (int i = 0; i < 8; ++i) {
      if ((m >> i & 1) != 0) t.pack32[m][n++] = i;
    }
  }
  for (int lane = 0; lane < 8; ++lane) {
    for (int i = 0; i < 8; ++i) t.others[lane][i] = i == lane ? 0 : -1;
  }
  return t;
}
inline constexpr EightLaneTable kEight = makeEightLaneTable();

/// FixedWalk's 14 fields (t[3], d[3], slack, steps, addr, flip, cross[3], index: 32 bits each)
/// as 14 rows of `stride` (n + 16 or more), walk i's in column i: the layout walkSixteenFixed
/// refills its lanes from.
constexpr int kFixedFields = 14;

/// Room for the marks pended (words and marks) of walks of `steps` steps in all.
template <class Word>
void pendRoom(std::size_t steps, std::vector<Word>& pend_w, std::vector<Word>& pend_b) {
  const std::size_t room = steps + 16;
  if (pend_w.size() < room) {
    pend_w.resize(std::max(room, 2 * pend_w.size()));
    pend_b.resize(pend_w.size());
  }
}
/// pendRoom, and room for the blocks entered.
inline void makeRoom(std::size_t steps, std::vector<std::uint32_t>& entered,
                     std::vector<std::uint64_t>& pend_w, std::vector<std::uint64_t>& pend_b) {
  const std::size_t room = steps + 16;
  if (entered.size() < room) entered.resize(std::max(room, 2 * entered.size()));
  pendRoom(steps, pend_w, pend_b);
}

namespace walks {
#ifdef DENSEMAP_WIDE_WALKS
/// walks_four.cpp
void walkFour(const DenseMarks::QueuedWalk* walks, std::size_t n, WideOut& out);
DenseMarks::BackWalkCounts walkFourBack(const DenseMarks::QueuedBackWalk* walks, std::size_t n,
                                        const std::uint64_t* culled, WideOut& out,
                                        std::vector<std::uint32_t>& handed_over);
/// walks_eight_fixed.cpp
std::size_t walkEightFixed(const DenseMarks::FixedWalk* walks, std::size_t n, std::uint32_t* pend_w,
                           std::uint32_t* pend_b, std::uint32_t* handed, std::size_t& n_handed);
DenseMarks::BackWalkCounts walkEightFixedBack(const DenseMarks::FixedWalk* walks, std::size_t n,
                                              const std::uint32_t* culled, std::uint32_t* pend_w,
                                              std::uint32_t* pend_b, std::uint32_t* handed,
                                              std::size_t& n_handed, std::size_t& n_pend);
/// walks_sixteen_fixed.cpp
void fixedColumns(const DenseMarks::FixedWalk* walks, std::size_t n, std::size_t stride,
                  std::int32_t* rows);
std::size_t fixedColumnsInto(const DenseMarks::FixedWalk* walks, std::size_t n,
                             std::vector<std::int32_t>& rows);
std::size_t walkSixteenFixed(const std::int32_t* rows, std::size_t stride, std::size_t n,
                             std::uint32_t* pend_w, std::uint32_t* pend_b, std::uint32_t* handed,
                             std::size_t& n_handed);
DenseMarks::BackWalkCounts walkSixteenFixedBack(const std::int32_t* rows, std::size_t stride,
                                                std::size_t n, const std::uint32_t* culled,
                                                std::uint32_t* pend_w, std::uint32_t* pend_b,
                                                std::uint32_t* handed, std::size_t& n_handed,
                                                std::size_t& n_pend);
#endif
}  // namespace walks
}  // namespace densemap
