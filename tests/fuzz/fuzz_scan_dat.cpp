// OctoMap scan.dat text files.
#include "densemap/io/scan_source.hpp"
#include "fuzz_input.hpp"

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  const auto file = densemap::fuzz::writeInput("s.dat", data, size);
  if (auto scans = densemap::readScanDat(file); scans) {
    for (const auto& s : *scans) (void)s.pointsWorld();
  }
  return 0;
}
