// A scan as it arrives off DDS (any pose, any coordinates, any lengths) through validation and,
// when accepted, the transform into the world frame.
#include "densemap/pipeline/scan_validator.hpp"
#include "fuzz_input.hpp"

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  densemap::fuzz::Reader in(data, size);
  densemap::RawScan raw;
  for (double& t : raw.t_world_sensor) t = in.take<double>();
  for (double& q : raw.q_world_sensor) q = in.take<double>();
  const std::uint8_t flags = in.take<std::uint8_t>();
  const std::size_t floats = in.restSize() / sizeof(float);
  std::vector<float> values(floats);
  std::memcpy(values.data(), in.rest(), floats * sizeof(float));
  if ((flags & 1) != 0 && !values.empty()) {  // intensities: the last third, whatever fits
    raw.intensity.assign(values.end() - static_cast<long>(values.size() / 3), values.end());
    values.resize(values.size() - values.size() / 3);
  }
  raw.xyz = std::move(values);
  densemap::ScanLimits limits;
  limits.max_points = 100000;
  if (auto scan = densemap::validateScan(raw, limits); scan) (void)scan->pointsWorld();
  return 0;
}
