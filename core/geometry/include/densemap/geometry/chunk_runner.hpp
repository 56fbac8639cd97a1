#pragma once

#include <cstddef>
#include <functional>

namespace densemap {

/// Runs body(begin, end) over [0, n) in chunks of about `grain` indices (the map and
/// its read side take one instead of naming a thread library, so a client links none).
/// serialRunner() runs the chunks in order on the caller's thread; the engine, the server and
/// the tools give the maps tbbRunner() (densemap::parallel), whose chunks may run at once, so a
/// body must only write what its own chunk owns.
class ChunkRunner {
 public:
  using Body = std::function<void(std::size_t begin, std::size_t end)>;
  virtual ~ChunkRunner() = default;
  virtual void run(std::size_t n, std::size_t grain, const Body& body) const = 0;
};

/// The chunks in order, on the caller's thread.
[[nodiscard]] const ChunkRunner& serialRunner();

}  // namespace densemap
