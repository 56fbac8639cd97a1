#include "densemap/foxglove/protocol.hpp"

#include <google/protobuf/util/json_util.h>

#include <algorithm>
#include <cstdio>

#include "foxglove_ws.pb.h"

namespace densemap::foxglove {
namespace {

namespace pbu = google::protobuf::util;

/// At most `n` characters of untrusted text, with control characters shown as '?'.
std::string excerpt(std::string_view text, std::size_t n = 64) {
  std::string s(text.substr(0, n));
  for (char& c : s) {
    if (static_cast<unsigned char>(c) < 0x20 || static_cast<unsigned char>(c) >= 0x7f) c = '?';
  }
  if (text.size() > n) s += "...";
  return s;
}

std::string toJson(const google::protobuf::Message& m) {
  std::string out;
  pbu::JsonPrintOptions options;
  options.always_print_primitive_fields = true;  // level 0 and empty lists are sent
  options.preserve_proto_field_names = false;    // lowerCamelCase, as the protocol names them
  (void)pbu::MessageToJsonString(m, &out, options);
  return out;
}

}  // namespace

bool offersSubprotocol(std::string_view value) {
  while (!value.empty()) {
    const std::size_t comma = value.find(',');
    std::string_view item = value.substr(0, comma);
    while (!item.empty() && (item.front() == ' ' || item.front() == '\t')) item.remove_prefix(1);
    while (!item.empty() && (item.back() == ' ' || item.back() == '\t')) item.remove_suffix(1);
    if (item == kSubprotocol) return true;
    if (comma == std::string_view::npos) break;
    value.remove_prefix(comma + 1);
  }
  return false;
}

Expected<ClientOp> parseClientText(std::string_view text) {
  if (text.size() > kMaxClientFrameBytes) {
    return makeError("a frame of " + std::to_string(text.size()) + " bytes (at most " +
                     std::to_string(kMaxClientFrameBytes) + ")");
  }
  foxglove_ws::ClientOp op;
  pbu::JsonParseOptions options;
  options.ignore_unknown_fields = true;  // fields of operations this server does not read
  if (const auto status = pbu::JsonStringToMessage(std::string(text), &op, options); !status.ok()) {
    return makeError("not a JSON operation this server reads: " +
                     excerpt(std::string(status.message()), 120));
  }
  if (op.op() == "subscribe") {
    if (op.subscriptions_size() == 0) return makeError("subscribe names no subscription");
    if (static_cast<std::size_t>(op.subscriptions_size()) > kMaxOpItems) {
      return makeError("subscribe names " + std::to_string(op.subscriptions_size()) +
                       " subscriptions (at most " + std::to_string(kMaxOpItems) + ")");
    }
    Subscribe s;
    s.subscriptions.reserve(static_cast<std::size_t>(op.subscriptions_size()));
    for (const auto& item : op.subscriptions()) {
      s.subscriptions.push_back({item.id(), item.channel_id()});
    }
    return s;
  }
  if (op.op() == "unsubscribe") {
    if (static_cast<std::size_t>(op.subscription_ids_size()) > kMaxOpItems) {
      return makeError("unsubscribe names " + std::to_string(op.subscription_ids_size()) +
                       " ids (at most " + std::to_string(kMaxOpItems) + ")");
    }
    Unsubscribe u;
    u.subscription_ids.assign(op.subscription_ids().begin(), op.subscription_ids().end());
    return u;
  }
  if (op.op().empty()) return makeError("a frame without \"op\"");
  static constexpr std::string_view kNeedCapability[] = {"advertise",
                                                         "unadvertise",
                                                         "getParameters",
                                                         "setParameters",
                                                         "subscribeParameterUpdates",
                                                         "unsubscribeParameterUpdates",
                                                         "subscribeConnectionGraph",
                                                         "unsubscribeConnectionGraph",
                                                         "fetchAsset",
                                                         "advertiseServices",
                                                         "unadvertiseServices"};
  if (std::ranges::find(kNeedCapability, std::string_view(op.op())) != std::end(kNeedCapability)) {
    return makeError("\"" + op.op() + "\" needs a capability this read-only server does not offer");
  }
  return makeError("unknown operation \"" + excerpt(op.op()) + "\"");
}

std::string binaryFrameError(std::span<const std::uint8_t> frame) {
  if (frame.empty()) return "an empty binary frame";
  char op[8];
  std::snprintf(op, sizeof op, "0x%02x", frame[0]);
  const char* what = frame[0] == 0x01   ? "client message data (needs clientPublish)"
                     : frame[0] == 0x02 ? "a service call request (needs services)"
                                        : "an unknown binary operation";
  return std::string("binary opcode ") + op + ": " + what +
         "; this read-only server offers no capability";
}

std::string serverInfoJson(std::string_view name, std::string_view session_id,
                           std::span<const std::pair<std::string, std::string>> metadata) {
  foxglove_ws::ServerInfo info;
  info.set_op("serverInfo");
  info.set_name(std::string(name));
  info.set_session_id(std::string(session_id));
  for (const auto& [k, v] : metadata) (*info.mutable_metadata())[k] = v;
  return toJson(info);
}

std::string advertiseJson(std::span<const ChannelInfo> channels) {
  foxglove_ws::Advertise a;
  a.set_op("advertise");
  for (const ChannelInfo& c : channels) {
    foxglove_ws::Channel* ch = a.add_channels();
    ch->set_id(c.id);
    ch->set_topic(c.topic);
    ch->set_encoding(c.encoding);
    ch->set_schema_name(c.schema_name);
    ch->set_schema(c.schema);
    ch->set_schema_encoding(c.schema_encoding);
  }
  return toJson(a);
}

std::string statusJson(StatusLevel level, std::string_view message) {
  foxglove_ws::Status s;
  s.set_op("status");
  s.set_level(static_cast<int>(level));
  s.set_message(std::string(message));
  return toJson(s);
}

std::array<std::uint8_t, kMessageDataHeaderBytes> messageDataHeader(std::uint32_t subscription_id,
                                                                    std::uint64_t timestamp_ns) {
  std::array<std::uint8_t, kMessageDataHeaderBytes> h{};
  h[0] = 0x01;
  for (int i = 0; i < 4; ++i) h[1 + i] = static_cast<std::uint8_t>(subscription_id >> (8 * i));
  for (int i = 0; i < 8; ++i) h[5 + i] = static_cast<std::uint8_t>(timestamp_ns >> (8 * i));
  return h;
}

std::string jsonString(std::string_view text) {
  std::string out = "\"";
  for (const char c : text) {
    const auto u = static_cast<unsigned char>(c);
    if (c == '"' || c == '\\') {
      out += '\\';
      out += c;
    } else if (u < 0x20) {
      char esc[8];
      std::snprintf(esc, sizeof esc, "\\u%04x", u);
      out += esc;
    } else {
      out += c;
    }
  }
  return out + "\"";
}

}  // namespace densemap::foxglove
