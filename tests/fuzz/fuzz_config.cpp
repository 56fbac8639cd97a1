// The server's textproto config, through every validation a start does.
#include "densemap/server/server_config.hpp"
#include "fuzz_input.hpp"

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  const auto file = densemap::fuzz::writeInput("c.textproto", data, size);
  if (auto config = densemap::server::loadServerConfig(file); config) {
    // Only the upsample model is read from disk: keep fuzzed configs from loading others.
    config->mutable_upsample()->set_model("/nonexistent/iln.pb");
    (void)densemap::server::pipelineOptions(*config);
    (void)densemap::server::ros2Options(*config);
  }
  return 0;
}
