// Scan store records (core/store): any bytes give a scan or a clear error, and a scan decoded
// encodes back to a record that decodes to the same scan.
#include <cstdlib>
#include <cstring>

#include "densemap/store/scan_store.hpp"

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  auto scan = densemap::decodeScanRecord({data, size});
  if (!scan) return 0;
  auto again = densemap::decodeScanRecord(densemap::encodeScanRecord(*scan));
  if (!again || again->sensor_id != scan->sensor_id || again->seq != scan->seq ||
      again->stamp_ns != scan->stamp_ns || again->xyz.size() != scan->xyz.size() ||
      std::memcmp(again->xyz.data(), scan->xyz.data(), scan->xyz.size() * sizeof(float)) != 0 ||
      again->intensity.size() != scan->intensity.size()) {
    std::abort();
  }
  return 0;
}
