#pragma once

// The Foxglove WebSocket protocol (foxglove.websocket.v1) as densemap's endpoint speaks it: a
// read-only server (no capabilities). Client text frames are parsed here, bounded, into the two
// operations a read-only server acts on; every other operation is refused with a reason. The
// server's JSON operations and the binary Message Data header are written here. No sockets:
// server/src/foxglove_room moves these bytes.
#include <array>
#include <cstddef>
#include <cstdint>
#include <span>
#include <string>
#include <string_view>
#include <utility>
#include <variant>
#include <vector>

#include "densemap/geometry/error.hpp"

namespace densemap::foxglove {

/// The subprotocol a client offers and the server selects in the WebSocket handshake.
inline constexpr std::string_view kSubprotocol = "foxglove.websocket.v1";
/// The largest client frame read; a larger one closes the connection (a subscribe naming every
/// channel is under 1 KiB).
inline constexpr std::size_t kMaxClientFrameBytes = 64 * 1024;
/// Subscriptions or subscription ids one operation may name.
inline constexpr std::size_t kMaxOpItems = 1024;

struct Subscribe {
  struct Item {
    std::uint32_t id = 0;          // the client's subscription id
    std::uint32_t channel_id = 0;  // an advertised channel
  };
  std::vector<Item> subscriptions;
};
struct Unsubscribe {
  std::vector<std::uint32_t> subscription_ids;
};
using ClientOp = std::variant<Subscribe, Unsubscribe>;

/// Whether a handshake's Sec-WebSocket-Protocol value (a comma-separated list) offers
/// kSubprotocol.
[[nodiscard]] bool offersSubprotocol(std::string_view header_value);

/// A client's text frame: `subscribe` or `unsubscribe`. Errors say why (not JSON, no `op`, an
/// operation that needs a capability this server does not offer, too many items, a number out
/// of range), in at most ~200 characters whatever the input.
[[nodiscard]] Expected<ClientOp> parseClientText(std::string_view text);

/// Why a client's binary frame is refused (client publish and service calls need capabilities
/// this server does not offer).
[[nodiscard]] std::string binaryFrameError(std::span<const std::uint8_t> frame);

/// An advertised channel.
struct ChannelInfo {
  std::uint32_t id = 0;
  std::string topic, encoding, schema_name, schema, schema_encoding;
};

/// Server operations (JSON text frames).
[[nodiscard]] std::string serverInfoJson(
    std::string_view name, std::string_view session_id,
    std::span<const std::pair<std::string, std::string>> metadata);
[[nodiscard]] std::string advertiseJson(std::span<const ChannelInfo> channels);
enum class StatusLevel { kInfo = 0, kWarning = 1, kError = 2 };
[[nodiscard]] std::string statusJson(StatusLevel level, std::string_view message);

/// The header of a Message Data frame: opcode 0x01, subscription id, timestamp (little-endian).
inline constexpr std::size_t kMessageDataHeaderBytes = 13;
[[nodiscard]] std::array<std::uint8_t, kMessageDataHeaderBytes> messageDataHeader(
    std::uint32_t subscription_id, std::uint64_t timestamp_ns);

/// `text` as a JSON string literal (quotes and escapes).
[[nodiscard]] std::string jsonString(std::string_view text);

}  // namespace densemap::foxglove
