// Snapshot files (.dmap): any bytes give a map or a clear error.
#include "densemap/store/snapshot.hpp"
#include "fuzz_input.hpp"

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  const auto file = densemap::fuzz::writeInput("s.dmap", data, size);
  (void)densemap::loadSnapshot(file, densemap::Backend::kGrid, 0.0);
  return 0;
}
