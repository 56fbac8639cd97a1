// PCD files (ASCII and binary).
#include "densemap/io/scan_source.hpp"
#include "fuzz_input.hpp"

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  const auto file = densemap::fuzz::writeInput("c.pcd", data, size);
  (void)densemap::readPcd(file);
  return 0;
}
