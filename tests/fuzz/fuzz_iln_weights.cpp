// ILN weights files (protobuf).
#include <string_view>

#include "densemap/upsample/iln.hpp"
#include "fuzz_input.hpp"

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  (void)densemap::upsample::IlnModel::parse(
      std::string_view(reinterpret_cast<const char*>(data), size), "fuzz");
  return 0;
}
