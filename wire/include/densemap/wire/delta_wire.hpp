#pragma once

#include "densemap/wire/dds.hpp"
#include "densemap/query/version_delta.hpp"

namespace densemap::dds {

/// The block layout shared by map/delta and map/tiles (block_keys, block_ends, cells,
/// log_odds), converted in one place for every message that carries it.

/// Points `msg`'s four sequences at `d`'s storage (no copy; `d` must outlive the write).
template <class Msg>
void borrowCells(Msg& msg, VersionDelta& d) {
  msg.block_keys = borrowSequence<decltype(msg.block_keys)>(d.block_keys);
  msg.block_ends = borrowSequence<decltype(msg.block_ends)>(d.block_ends);
  msg.cells = borrowSequence<decltype(msg.cells)>(d.cells);
  msg.log_odds = borrowSequence<decltype(msg.log_odds)>(d.log_odds);
}

/// Copies `msg`'s four sequences; check wellFormed() before reading the result.
template <class Msg>
[[nodiscard]] VersionDelta cellsFrom(const Msg& msg) {
  VersionDelta d;
  d.block_keys.assign(msg.block_keys._buffer, msg.block_keys._buffer + msg.block_keys._length);
  d.block_ends.assign(msg.block_ends._buffer, msg.block_ends._buffer + msg.block_ends._length);
  d.cells.assign(msg.cells._buffer, msg.cells._buffer + msg.cells._length);
  d.log_odds.assign(msg.log_odds._buffer, msg.log_odds._buffer + msg.log_odds._length);
  return d;
}

}  // namespace densemap::dds
