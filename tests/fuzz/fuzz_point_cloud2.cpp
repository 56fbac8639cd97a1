// sensor_msgs/PointCloud2 as received: the layout (fields, steps, sizes) and the data bytes
// all from the input.
#include "densemap/ros2/point_cloud2.hpp"
#include "fuzz_input.hpp"

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  densemap::fuzz::Reader in(data, size);
  densemap::ros2::PointCloud2View v;
  v.height = in.take<std::uint32_t>();
  v.width = in.take<std::uint32_t>();
  v.point_step = in.take<std::uint32_t>();
  v.row_step = in.take<std::uint32_t>();
  v.is_bigendian = (in.take<std::uint8_t>() & 1) != 0;
  static const char* kNames[] = {"x", "y", "z", "intensity", "ring", ""};
  const std::uint8_t n = in.take<std::uint8_t>() % 7;
  std::vector<densemap::ros2::PointFieldView> fields;
  for (std::uint8_t i = 0; i < n; ++i) {
    densemap::ros2::PointFieldView f;
    f.name = kNames[in.take<std::uint8_t>() % 6];
    f.offset = in.take<std::uint32_t>();
    f.datatype = in.take<std::uint8_t>();
    f.count = in.take<std::uint8_t>();
    fields.push_back(f);
  }
  v.fields = fields;
  // The data is its own heap copy, so ASan sees any read past its end.
  std::vector<std::uint8_t> bytes(in.rest(), in.rest() + in.restSize());
  v.data = bytes;
  (void)densemap::ros2::decodePointCloud2(v, 1 << 20);
  return 0;
}
