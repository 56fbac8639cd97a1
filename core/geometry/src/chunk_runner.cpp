#include "densemap/geometry/chunk_runner.hpp"

#include <algorithm>

namespace densemap {
namespace {

class SerialRunner final : public ChunkRunner {
 public:
  void run(std::size_t n, std::size_t grain, const Body& body) const override {
    const std::size_t step = std::max<std::size_t>(grain, 1);
    for (std::size_t begin = 0; begin < n; begin += step) body(begin, std::min(n, begin + step));
  }
};

}  // namespace

const ChunkRunner& serialRunner() {
  static const SerialRunner runner;
  return runner;
}

}  // namespace densemap
