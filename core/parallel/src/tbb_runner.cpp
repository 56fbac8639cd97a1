#include "densemap/parallel/tbb_runner.hpp"

#include <tbb/blocked_range.h>
#include <tbb/parallel_for.h>

#include <algorithm>

namespace densemap {
namespace {

class TbbRunner final : public ChunkRunner {
 public:
  void run(std::size_t n, std::size_t grain, const Body& body) const override {
    tbb::parallel_for(tbb::blocked_range<std::size_t>(0, n, std::max<std::size_t>(grain, 1)),
                      [&](const tbb::blocked_range<std::size_t>& r) { body(r.begin(), r.end()); });
  }
};

}  // namespace

const ChunkRunner& tbbRunner() {
  static const TbbRunner runner;
  return runner;
}

}  // namespace densemap
