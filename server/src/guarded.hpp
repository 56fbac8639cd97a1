#pragma once

#include <spdlog/spdlog.h>

#include <string_view>

#include "densemap/cli/guarded_main.hpp"

namespace densemap {

/// Runs one turn of a server thread's loop. Whatever the turn throws (out of memory, a bug) is
/// logged and the thread goes on to its next turn: no exception ends the daemon through
/// std::terminate. Failures a caller counts (a rejected scan, a failed command) are caught
/// closer to them; this is the last line.
template <class Turn>
void guarded(std::string_view thread, Turn&& turn) noexcept {
  try {
    turn();
  } catch (...) {
    try {
      spdlog::error("{}: {} (the thread goes on)", thread, cli::currentFailure());
    } catch (...) {
    }
  }
}

}  // namespace densemap
