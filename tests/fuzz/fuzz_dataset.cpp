// The dataset directory: poses.txt and a scan .bin from one input (the first two bytes say
// how many of the rest are poses.txt).
#include "densemap/io/scan_source.hpp"
#include "fuzz_input.hpp"

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  densemap::fuzz::Reader in(data, size);
  const std::size_t split = std::min<std::size_t>(in.take<std::uint16_t>(), in.restSize());
  (void)densemap::fuzz::writeInput("d/poses.txt", in.rest(), split);
  (void)densemap::fuzz::writeInput("d/scans/000000.bin", in.rest() + split, in.restSize() - split);
  if (auto source = densemap::openScanSource(densemap::fuzz::workDir() / "d"); source) {
    for (std::size_t i = 0; i < (*source)->size() && i < 4; ++i) {
      if (auto scan = (*source)->load(i); scan) (void)scan->pointsWorld();
    }
  }
  return 0;
}
