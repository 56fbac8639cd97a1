#pragma once

#include "densemap/geometry/chunk_runner.hpp"

namespace densemap {

/// Chunks as TBB tasks (tbb::parallel_for over blocked ranges of `grain`), in the calling
/// thread's task arena: what the engine, the server and the tools give their maps.
[[nodiscard]] const ChunkRunner& tbbRunner();

}  // namespace densemap
