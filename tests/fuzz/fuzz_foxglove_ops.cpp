// What a Foxglove client sends the server, as the endpoint reads it (foxglove/src/protocol.cpp):
// the first byte picks a text frame (the JSON operation parser), a binary frame (its refusal)
// or a handshake's Sec-WebSocket-Protocol value. Nothing may crash, hang, leak or answer with
// an unbounded reason. The WebSocket framing and HTTP parsing are Boost.Beast's.
#include <cstdint>
#include <cstdlib>
#include <span>
#include <string_view>

#include "densemap/foxglove/protocol.hpp"

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  if (size == 0) return 0;
  const std::string_view rest(reinterpret_cast<const char*>(data + 1), size - 1);
  switch (data[0] % 3) {
    case 0: {
      const auto op = densemap::foxglove::parseClientText(rest);
      if (!op && op.error().message.size() > 400) std::abort();
      if (op) {
        if (const auto* s = std::get_if<densemap::foxglove::Subscribe>(&*op)) {
          if (s->subscriptions.empty() ||
              s->subscriptions.size() > densemap::foxglove::kMaxOpItems) {
            std::abort();
          }
        }
      }
      break;
    }
    case 1:
      if (densemap::foxglove::binaryFrameError({data + 1, size - 1}).size() > 400) std::abort();
      break;
    default:
      (void)densemap::foxglove::offersSubprotocol(rest);
  }
  return 0;
}
