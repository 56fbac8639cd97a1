#include "foxglove_room.hpp"

#include <spdlog/spdlog.h>
#include <sys/resource.h>
#include <unistd.h>

#include <boost/asio.hpp>
#include <boost/asio/ssl.hpp>
#include <boost/beast/core.hpp>
#include <boost/beast/http.hpp>
#include <boost/beast/ssl.hpp>
#include <boost/beast/websocket.hpp>
#include <boost/beast/websocket/ssl.hpp>

#include <chrono>
#include <deque>
#include <map>
#include <mutex>
#include <optional>
#include <string_view>
#include <thread>
#include <unordered_map>
#include <unordered_set>
#include <vector>

#include "densemap/foxglove/encoders.hpp"
#include "densemap/foxglove/protocol.hpp"
#include "densemap/ros2/cdr.hpp"
#include "densemap/ros2/map_topics.hpp"
#include "densemap/ros2/msg_definitions.hpp"
#include "guarded.hpp"

namespace densemap::server {
namespace {

namespace net = boost::asio;
namespace ssl = boost::asio::ssl;
namespace beast = boost::beast;
namespace http = beast::http;
namespace websocket = beast::websocket;
using tcp = net::ip::tcp;
using Clock = std::chrono::steady_clock;
using Payload = std::shared_ptr<const std::string>;

// The channels, with fixed ids (a reconnecting client sees the same ids).
enum Channel : std::uint32_t {
  kMap = 1,
  kGrid = 2,
  kScan = 3,
  kTransforms = 4,
  kTrajectories = 5,
  kStatus = 6,
  kVoxels = 7,
};

// A map-channel message holds layers up to about this many bytes, and the map channel adds
// messages to a client's queue only while it holds less than kMapQueueBytes (or half the
// queue): each client's catch-up is its own copy, so this bounds their memory together.
constexpr std::size_t kMapMessageBytes = 256 * 1024;
constexpr std::size_t kMapQueueBytes = 2 * 1024 * 1024;
// Versions whose written blocks wait for the endpoint's thread, beyond which it re-reads the
// whole map instead (the thread was held up: coalesced, never unbounded).
constexpr std::size_t kMaxPendingBlocks = std::size_t{1} << 22;
constexpr std::size_t kMaxPendingPoses = 4096;
constexpr std::size_t kMaxHttpHeaderBytes = 8 * 1024;
constexpr int kThreadNice = 10;
// How many sensors keep a trajectory and a pose (a sensor id past them is not shown): with
// max_trajectory_poses each, a trajectories message stays within a client's queue.
constexpr std::size_t kMaxSensorsShown = 64;

std::vector<foxglove::ChannelInfo> channelsFor(const FoxgloveOptions& o) {
  const std::string scene = foxglove::protobufSchema("foxglove.SceneUpdate");
  std::vector<foxglove::ChannelInfo> c{
      {kMap, "/densemap/occupied", "protobuf", "foxglove.SceneUpdate", scene, "protobuf"},
      {kGrid, "/densemap/grid", "cdr", "nav_msgs/msg/OccupancyGrid",
       ros2::occupancyGridDefinition(), "ros2msg"},
      {kScan, "/densemap/scan", "cdr", "sensor_msgs/msg/PointCloud2", ros2::pointCloud2Definition(),
       "ros2msg"},
      {kTransforms, "/tf", "protobuf", "foxglove.FrameTransforms",
       foxglove::protobufSchema("foxglove.FrameTransforms"), "protobuf"},
      {kTrajectories, "/densemap/trajectories", "protobuf", "foxglove.SceneUpdate", scene,
       "protobuf"},
      {kStatus, "/densemap/status", "json", "densemap.Status", foxglove::statusJsonSchema(),
       "jsonschema"},
  };
  if (o.voxels) {
    c.push_back({kVoxels, "/densemap/voxels", "protobuf", "foxglove.VoxelGrid",
                 foxglove::protobufSchema("foxglove.VoxelGrid"), "protobuf"});
  }
  return c;
}

std::int64_t wallNowNs() {
  return std::chrono::duration_cast<std::chrono::nanoseconds>(
             std::chrono::system_clock::now().time_since_epoch())
      .count();
}

/// One frame waiting in a client's queue: a Message Data header and payload (binary), or a
/// JSON operation (text). The payload is the concatenation of its parts (the map channel's
/// layers), each shared by every client it goes to, never copied into one string per client.
struct Frame {
  std::array<std::uint8_t, foxglove::kMessageDataHeaderBytes> header{};
  bool binary = true;
  std::vector<Payload> parts;
  std::size_t size = 0;  // the parts' bytes
  [[nodiscard]] std::size_t bytes() const { return size + (binary ? header.size() : 0); }
};

}  // namespace

/// A client connection, whatever its stream (ws or wss): its send queue and subscriptions.
/// Everything runs on the endpoint's one thread.
struct SessionBase : std::enable_shared_from_this<SessionBase> {
  explicit SessionBase(FoxgloveRoom::Impl& r, std::uint64_t i) : room(r), id(i) {}
  virtual ~SessionBase() = default;
  virtual void begin() = 0;
  virtual void writeFront() = 0;
  virtual void closeNow() = 0;

  FoxgloveRoom::Impl& room;
  std::uint64_t id;
  bool open = false;  // the WebSocket handshake is done
  bool closing = false;
  std::deque<Frame> queue;
  std::size_t queued_bytes = 0;
  bool writing = false;
  Clock::time_point write_began{};
  std::unordered_map<std::uint32_t, std::uint32_t> subscription_of;  // channel -> client's id
  std::unordered_map<std::uint32_t, std::uint32_t> channel_of;       // client's id -> channel
  // The map channel: layers this client has not been sent at their cached content.
  std::vector<std::uint64_t> dirty_list;
  std::unordered_set<std::uint64_t> dirty;
  bool marker_due = false;
};

struct FoxgloveRoom::Impl {
  explicit Impl(const FoxgloveOptions& o) : options(o), channels(channelsFor(o)) {}

  FoxgloveOptions options;
  net::io_context ioc{1};  // first: destroyed last, after everything that refers to it
  std::optional<ssl::context> tls;
  tcp::acceptor acceptor{ioc};
  net::steady_timer ticker{ioc};
  std::thread thread;
  std::atomic<bool> running{false};
  std::vector<foxglove::ChannelInfo> channels;
  std::string server_info, advertise;
  std::atomic<std::uint64_t> n_clients{0}, n_dropped{0}, n_closed{0}, n_rejected{0};

  // The endpoint's thread only.
  std::unordered_map<std::uint64_t, std::shared_ptr<SessionBase>> sessions;
  std::uint64_t next_session = 1;
  std::shared_ptr<const MapView> view;
  // The map channel's layers (foxglove::layerOf) with an occupied cell, kept while anyone
  // subscribes: which cells are occupied and the encoded SceneUpdate field.
  struct ShownLayer {
    std::uint64_t occupied = 0;
    Payload field;
  };
  std::unordered_map<std::uint64_t, ShownLayer> layers;
  bool layers_valid = false;
  std::uint64_t layers_version = 0;
  Payload last_grid, last_scan, last_transforms, last_trajectories, last_status, last_voxels;
  std::map<std::string, std::deque<Point3f>> paths;
  std::map<std::string, foxglove::Pose> poses;
  bool paths_changed = false;
  std::uint64_t grid_version = ~std::uint64_t{0}, voxel_version = ~std::uint64_t{0};
  Point3f robot = Point3f::Zero();
  Clock::time_point next_period = Clock::now();

  // Handed over from other threads (onVersion, onStatus), drained on the endpoint's thread.
  struct Pending {
    std::shared_ptr<const MapView> view;
    std::vector<std::uint64_t> blocks;
    bool all_blocks = false;  // too many waited: re-read the whole map
    std::shared_ptr<const PointCloud> scan;
    std::int64_t scan_stamp_ns = 0;
    std::vector<foxglove::Pose> poses;
    std::optional<ServerStatus> status;
  };
  std::mutex mutex;
  Pending pending;
  bool drain_posted = false;
  /// Any thread: `fill(pending)` under the lock, then one drain posted for all that waits.
  template <class Fill>
  void handOver(Fill&& fill) {
    bool post = false;
    {
      std::lock_guard lock(mutex);
      fill(pending);
      post = !std::exchange(drain_posted, true);
    }
    if (post) net::post(ioc, [this] { guarded("foxglove", [&] { drain(); }); });
  }

  // ---- connections ----
  void acceptNext();
  void spawn(tcp::socket socket);
  void remove(const std::shared_ptr<SessionBase>& s, bool stalled);
  void reject() { n_rejected.fetch_add(1, std::memory_order_relaxed); }

  // ---- sending ----
  /// Queues a frame unless it does not fit (then dropped and counted); `force`: queued anyway
  /// (the handshake's operations, and the map channel's, sent only when the queue has room).
  void enqueue(SessionBase& s, Frame frame, bool force = false) {
    if (s.closing) return;
    if (!force && s.queued_bytes + frame.bytes() > options.max_queue_bytes) {
      n_dropped.fetch_add(1, std::memory_order_relaxed);
      return;
    }
    s.queued_bytes += frame.bytes();
    s.queue.push_back(std::move(frame));
    if (!s.writing) s.writeFront();
  }
  /// A JSON operation: `force` for the handshake's (serverInfo, advertise); a status answering
  /// a client's frame is dropped like any frame when the queue is full, so a client that sends
  /// bad frames and never reads cannot grow its queue.
  void sendText(SessionBase& s, std::string text, bool force) {
    Frame f;
    f.binary = false;
    f.size = text.size();
    f.parts.push_back(std::make_shared<const std::string>(std::move(text)));
    enqueue(s, std::move(f), force);
  }
  void sendMessage(SessionBase& s, std::uint32_t channel, std::vector<Payload> parts,
                   std::size_t size, bool force) {
    const auto it = s.subscription_of.find(channel);
    if (it == s.subscription_of.end()) return;
    Frame f;
    f.header = foxglove::messageDataHeader(it->second, static_cast<std::uint64_t>(wallNowNs()));
    f.parts = std::move(parts);
    f.size = size;
    enqueue(s, std::move(f), force);
  }
  void sendMessage(SessionBase& s, std::uint32_t channel, const Payload& payload, bool force) {
    sendMessage(s, channel, std::vector<Payload>{payload}, payload->size(), force);
  }
  void broadcast(std::uint32_t channel, const Payload& payload) {
    for (auto& [id, s] : sessions) sendMessage(*s, channel, payload, false);
  }
  [[nodiscard]] bool anyoneOn(std::uint32_t channel) const {
    for (const auto& [id, s] : sessions) {
      if (s->subscription_of.contains(channel)) return true;
    }
    return false;
  }
  void onWritten(const std::shared_ptr<SessionBase>& s, beast::error_code ec) {
    s->writing = false;
    if (ec) return remove(s, false);
    if (s->closing || s->queue.empty()) return;
    s->queued_bytes -= s->queue.front().bytes();
    s->queue.pop_front();
    pumpMap(*s);
    if (!s->queue.empty() && !s->writing) s->writeFront();
  }

  // ---- client operations ----
  void onOpen(const std::shared_ptr<SessionBase>& s) {
    s->open = true;
    n_clients.fetch_add(1, std::memory_order_relaxed);
    sendText(*s, server_info, true);
    sendText(*s, advertise, true);
  }
  void onClientFrame(SessionBase& s, bool text, std::string_view bytes);
  void subscribe(SessionBase& s, std::uint32_t sub, std::uint32_t channel);
  void unsubscribe(SessionBase& s, std::uint32_t sub);
  void error(SessionBase& s, const std::string& why) {
    reject();
    sendText(s, foxglove::statusJson(foxglove::StatusLevel::kError, why), false);
  }

  // ---- the map channel ----
  /// Brings a block's layers to `occupied`; calls changed(layer) for each that changed.
  template <class Changed>
  void showBlock(std::uint64_t key, const block::BlockMask& occupied, Changed&& changed) {
    for (int z = 0; z < block::kEdge; ++z) {
      const std::uint64_t layer = foxglove::layerOf(key, z);
      const std::uint64_t word = occupied[static_cast<std::size_t>(z)];
      const auto it = layers.find(layer);
      if (word == 0) {
        if (it == layers.end()) continue;
        layers.erase(it);
      } else {
        // The same cells occupied: the entity is the same, nothing is resent.
        if (it != layers.end() && it->second.occupied == word) continue;
        layers[layer] =
            ShownLayer{word, std::make_shared<const std::string>(
                                 foxglove::layerEntityField(view->grid(), layer, word))};
      }
      changed(layer);
    }
  }
  void buildLayers() {
    layers.clear();
    view->forEachBlock([&](std::uint64_t key, const VoxelBlock& block) {
      showBlock(key, foxglove::occupiedCells(block), [](std::uint64_t) {});
    });
    layers_valid = true;
    layers_version = view->version();
  }
  void markDirty(SessionBase& s, std::uint64_t key) {
    if (s.dirty.insert(key).second) s.dirty_list.push_back(key);
  }
  void updateLayers(const std::vector<std::uint64_t>& written, bool all);
  void pumpMap(SessionBase& s);

  // ---- the other channels ----
  void drain();
  void tick();
  void periodic();
};

// ---------------------------------------------------------------------------------------------
// Sessions

namespace {

template <bool kTls>
class Session final : public SessionBase {
 public:
  using Layer = std::conditional_t<kTls, beast::ssl_stream<beast::tcp_stream>, beast::tcp_stream>;

  Session(FoxgloveRoom::Impl& owner, std::uint64_t session_id, tcp::socket socket)
      : SessionBase(owner, session_id), ws_(makeStream(owner, std::move(socket))) {}

  void begin() override {
    auto self = shared_from_this();
    beast::get_lowest_layer(ws_).expires_after(std::chrono::duration_cast<Clock::duration>(
        std::chrono::duration<double>(room.options.handshake_timeout_s)));
    if constexpr (kTls) {
      ws_.next_layer().async_handshake(ssl::stream_base::server,
                                       [this, self](beast::error_code ec) {
                                         if (ec) {
                                           room.reject();
                                           return room.remove(self, false);
                                         }
                                         readRequest();
                                       });
    } else {
      readRequest();
    }
  }

  void writeFront() override {
    Frame& f = queue.front();
    writing = true;
    write_began = Clock::now();
    ws_.binary(f.binary);
    auto self = shared_from_this();
    auto done = [this, self](beast::error_code ec, std::size_t) { room.onWritten(self, ec); };
    buffers_.clear();
    if (f.binary) buffers_.push_back(net::buffer(f.header));
    for (const Payload& part : f.parts) buffers_.push_back(net::buffer(*part));
    ws_.async_write(buffers_, std::move(done));
  }

  void closeNow() override {
    closing = true;
    beast::error_code ec;
    beast::get_lowest_layer(ws_).socket().shutdown(tcp::socket::shutdown_both, ec);
    beast::get_lowest_layer(ws_).close();
  }

 private:
  static auto makeStream(FoxgloveRoom::Impl& room, tcp::socket socket) {
    if constexpr (kTls) {
      return websocket::stream<Layer>(std::move(socket), *room.tls);
    } else {
      return websocket::stream<Layer>(std::move(socket));
    }
  }

  void readRequest() {
    auto self = shared_from_this();
    parser_.emplace();
    parser_->header_limit(kMaxHttpHeaderBytes);
    http::async_read(ws_.next_layer(), buffer_, *parser_,
                     [this, self](beast::error_code ec, std::size_t) {
                       if (ec) {
                         // A connection closed before sending anything (a port probe) is not
                         // counted; a bad or slow request is.
                         if (ec != http::error::end_of_stream) room.reject();
                         return room.remove(self, false);
                       }
                       upgrade(parser_->release());
                     });
  }

  void upgrade(http::request<http::empty_body> request) {
    auto self = shared_from_this();
    const auto offered = request[http::field::sec_websocket_protocol];
    if (!websocket::is_upgrade(request) ||
        !foxglove::offersSubprotocol(std::string_view(offered.data(), offered.size()))) {
      room.reject();
      // A plain HTTP answer for a person who opened the address in a browser or with curl.
      auto response = std::make_shared<http::response<http::string_body>>(http::status::bad_request,
                                                                          request.version());
      response->set(http::field::content_type, "text/plain");
      response->body() =
          "densemap: a Foxglove WebSocket endpoint. Open it in Foxglove or Lichtblick (Open "
          "connection, Foxglove WebSocket); clients must offer the subprotocol " +
          std::string(foxglove::kSubprotocol) + ".\n";
      response->keep_alive(false);
      response->prepare_payload();
      http::async_write(
          ws_.next_layer(), *response,
          [this, self, response](beast::error_code, std::size_t) { room.remove(self, false); });
      return;
    }
    beast::get_lowest_layer(ws_).expires_never();
    websocket::stream_base::timeout timeouts{};
    timeouts.handshake_timeout = std::chrono::duration_cast<Clock::duration>(
        std::chrono::duration<double>(room.options.handshake_timeout_s));
    timeouts.idle_timeout = std::chrono::seconds(30);  // pinged at 15 s; a dead peer goes
    timeouts.keep_alive_pings = true;
    ws_.set_option(timeouts);
    ws_.set_option(websocket::stream_base::decorator([](websocket::response_type& response) {
      response.set(http::field::sec_websocket_protocol, std::string(foxglove::kSubprotocol));
      response.set(http::field::server, "densemap");
    }));
    ws_.read_message_max(foxglove::kMaxClientFrameBytes);
    ws_.auto_fragment(false);
    ws_.async_accept(request, [this, self](beast::error_code ec) {
      if (ec) {
        room.reject();
        return room.remove(self, false);
      }
      room.onOpen(self);
      readNext();
    });
  }

  void readNext() {
    auto self = shared_from_this();
    ws_.async_read(buffer_, [this, self](beast::error_code ec, std::size_t) {
      if (ec) {
        if (ec == websocket::error::message_too_big) room.reject();
        return room.remove(self, false);
      }
      const auto data = buffer_.cdata();
      room.onClientFrame(*this, ws_.got_text(),
                         std::string_view(static_cast<const char*>(data.data()), data.size()));
      buffer_.consume(buffer_.size());
      if (!closing) readNext();
    });
  }

  websocket::stream<Layer> ws_;
  std::vector<net::const_buffer> buffers_;  // the frame being written
  beast::flat_buffer buffer_;
  std::optional<http::request_parser<http::empty_body>> parser_;
};

}  // namespace

void FoxgloveRoom::Impl::acceptNext() {
  acceptor.async_accept([this](beast::error_code ec, tcp::socket socket) {
    if (!running.load()) return;
    if (!ec) {
      if (sessions.size() >= options.max_clients) {
        reject();  // over max_clients: closed at once
        beast::error_code ignored;
        socket.close(ignored);
      } else {
        spawn(std::move(socket));
      }
    }
    acceptNext();
  });
}

void FoxgloveRoom::Impl::spawn(tcp::socket socket) {
  const std::uint64_t id = next_session++;
  std::shared_ptr<SessionBase> s;
  if (tls) {
    s = std::make_shared<Session<true>>(*this, id, std::move(socket));
  } else {
    s = std::make_shared<Session<false>>(*this, id, std::move(socket));
  }
  sessions.emplace(id, s);
  s->begin();
}

void FoxgloveRoom::Impl::remove(const std::shared_ptr<SessionBase>& s, bool stalled) {
  if (sessions.erase(s->id) == 0) return;
  if (s->open) n_clients.fetch_sub(1, std::memory_order_relaxed);
  if (stalled) n_closed.fetch_add(1, std::memory_order_relaxed);
  // The queue goes with the session, once no operation in flight refers to it.
  if (!s->closing) s->closeNow();
  if (layers_valid && !anyoneOn(kMap)) {  // nobody watches the map: its layers are let go
    layers.clear();
    layers_valid = false;
  }
}

// ---------------------------------------------------------------------------------------------
// Client operations

void FoxgloveRoom::Impl::onClientFrame(SessionBase& s, bool text, std::string_view bytes) {
  if (!text) {
    return error(s, foxglove::binaryFrameError(std::span<const std::uint8_t>(
                        reinterpret_cast<const std::uint8_t*>(bytes.data()), bytes.size())));
  }
  auto op = foxglove::parseClientText(bytes);
  if (!op) return error(s, op.error().message);
  if (const auto* sub = std::get_if<foxglove::Subscribe>(&*op)) {
    for (const auto& item : sub->subscriptions) subscribe(s, item.id, item.channel_id);
  } else {
    for (const std::uint32_t id : std::get<foxglove::Unsubscribe>(*op).subscription_ids) {
      unsubscribe(s, id);
    }
  }
}

void FoxgloveRoom::Impl::subscribe(SessionBase& s, std::uint32_t sub, std::uint32_t channel) {
  const bool known = std::ranges::any_of(
      channels, [&](const foxglove::ChannelInfo& c) { return c.id == channel; });
  if (!known) return error(s, "subscribe: no channel " + std::to_string(channel));
  if (s.channel_of.contains(sub)) {
    return error(s, "subscribe: subscription id " + std::to_string(sub) + " is in use");
  }
  if (s.subscription_of.contains(channel)) {
    return error(s, "subscribe: channel " + std::to_string(channel) + " is already subscribed");
  }
  s.subscription_of.emplace(channel, sub);
  s.channel_of.emplace(sub, channel);
  switch (channel) {
    case kMap:
      // The whole map first (every layer with an occupied cell), then what versions change.
      if (!layers_valid) buildLayers();
      s.dirty.clear();
      s.dirty_list.clear();
      for (const auto& [layer, shown] : layers) markDirty(s, layer);
      s.marker_due = true;
      pumpMap(s);
      break;
    case kGrid:
      grid_version = ~std::uint64_t{0};  // sent at the next period
      break;
    case kVoxels:
      voxel_version = ~std::uint64_t{0};
      break;
    default: {
      const Payload* latest = channel == kScan           ? &last_scan
                              : channel == kTransforms   ? &last_transforms
                              : channel == kTrajectories ? &last_trajectories
                                                         : &last_status;
      if (*latest) sendMessage(s, channel, *latest, false);
    }
  }
}

void FoxgloveRoom::Impl::unsubscribe(SessionBase& s, std::uint32_t sub) {
  const auto it = s.channel_of.find(sub);
  if (it == s.channel_of.end()) {
    return error(s, "unsubscribe: no subscription " + std::to_string(sub));
  }
  const std::uint32_t channel = it->second;
  s.channel_of.erase(it);
  s.subscription_of.erase(channel);
  if (channel == kMap) {
    s.dirty.clear();
    s.dirty_list.clear();
    s.marker_due = false;
    if (!anyoneOn(kMap)) {
      layers.clear();
      layers_valid = false;
    }
  }
}

// ---------------------------------------------------------------------------------------------
// The map channel

void FoxgloveRoom::Impl::updateLayers(const std::vector<std::uint64_t>& written, bool all) {
  if (!layers_valid) return;
  std::vector<std::uint64_t> changed;
  const auto note = [&](std::uint64_t layer) { changed.push_back(layer); };
  if (all) {
    std::unordered_map<std::uint64_t, ShownLayer> before = std::move(layers);
    buildLayers();
    for (const auto& [layer, shown] : before) {
      const auto it = layers.find(layer);
      if (it == layers.end() || it->second.occupied != shown.occupied) note(layer);
    }
    for (const auto& [layer, shown] : layers) {
      if (!before.contains(layer)) note(layer);
    }
  } else {
    for (const std::uint64_t key : written) {
      const VoxelBlock* block = view->block(key);
      showBlock(key, block != nullptr ? foxglove::occupiedCells(*block) : block::BlockMask{}, note);
    }
    layers_version = view->version();
  }
  for (auto& [id, s] : sessions) {
    if (!s->subscription_of.contains(kMap)) continue;
    for (const std::uint64_t key : changed) markDirty(*s, key);
    s->marker_due = true;
  }
}

void FoxgloveRoom::Impl::pumpMap(SessionBase& s) {
  if (!s.subscription_of.contains(kMap) || !layers_valid) return;
  // Only while the queue holds less than kMapQueueBytes (or half of max_queue_bytes): the map
  // channel waits for a slow client (it catches up with the layers' latest content) instead
  // of losing cells.
  const std::size_t fill = std::min(kMapQueueBytes, options.max_queue_bytes / 2);
  while (s.queued_bytes < fill && (!s.dirty_list.empty() || s.marker_due)) {
    std::vector<Payload> parts;
    std::size_t size = 0;
    const auto add = [&](Payload part) {
      size += part->size();
      parts.push_back(std::move(part));
    };
    while (!s.dirty_list.empty() && size < kMapMessageBytes) {
      const std::uint64_t key = s.dirty_list.back();
      s.dirty_list.pop_back();
      s.dirty.erase(key);
      const auto it = layers.find(key);
      add(it != layers.end()
              ? it->second.field
              : std::make_shared<const std::string>(foxglove::layerDeletionField(key)));
    }
    if (s.dirty_list.empty()) {
      add(std::make_shared<const std::string>(foxglove::versionMarkerField(layers_version)));
      s.marker_due = false;
    }
    sendMessage(s, kMap, std::move(parts), size, true);
  }
}

// ---------------------------------------------------------------------------------------------
// The other channels

void FoxgloveRoom::Impl::drain() {
  Pending p;
  {
    std::lock_guard lock(mutex);
    p = std::move(pending);
    pending = Pending{};
    drain_posted = false;
  }
  if (p.view) {
    view = std::move(p.view);
    updateLayers(p.blocks, p.all_blocks);
  }
  const std::int64_t now = wallNowNs();
  if (p.scan && anyoneOn(kScan)) {
    const std::span<const float> xyz(p.scan->empty() ? nullptr : p.scan->front().data(),
                                     p.scan->size() * 3);
    last_scan = std::make_shared<const std::string>(
        ros2::encodeCdrPointCloud2({p.scan_stamp_ns != 0 ? p.scan_stamp_ns : now, "map"}, xyz));
    broadcast(kScan, last_scan);
  }
  if (!p.poses.empty()) {
    for (const foxglove::Pose& pose : p.poses) {
      if (!poses.contains(pose.child) && poses.size() >= kMaxSensorsShown) continue;
      poses[pose.child] = pose;
      auto& path = paths[pose.child];
      path.emplace_back(static_cast<float>(pose.t[0]), static_cast<float>(pose.t[1]),
                        static_cast<float>(pose.t[2]));
      while (path.size() > options.max_trajectory_poses) path.pop_front();
      robot = path.back();
    }
    paths_changed = true;
    std::vector<foxglove::Pose> all;
    for (const auto& [id, pose] : poses) all.push_back(pose);
    last_transforms = std::make_shared<const std::string>(foxglove::frameTransforms("map", all));
    broadcast(kTransforms, last_transforms);
  }
  if (p.status) {
    ServerStatus& st = *p.status;
    st.foxglove_enabled = true;
    st.foxglove_clients = n_clients.load();
    st.foxglove_dropped_frames = n_dropped.load();
    st.foxglove_closed_clients = n_closed.load();
    st.foxglove_rejected = n_rejected.load();
    last_status = std::make_shared<const std::string>(foxglove::statusObject(st));
    broadcast(kStatus, last_status);
  }
  for (auto& [id, s] : sessions) pumpMap(*s);
}

void FoxgloveRoom::Impl::periodic() {
  if (!view) return;
  if (anyoneOn(kGrid) && view->version() != grid_version) {
    grid_version = view->version();
    const ros2::GridImage grid =
        ros2::MapTopicsState::project(*view, options.grid_min_z_m, options.grid_max_z_m);
    // In the plane z = 0, as the ROS 2 face's /projected_map.
    last_grid = std::make_shared<const std::string>(
        ros2::encodeCdrOccupancyGrid({wallNowNs(), "map"}, grid, 0.0));
    broadcast(kGrid, last_grid);
  }
  if (paths_changed && anyoneOn(kTrajectories)) {
    paths_changed = false;
    std::vector<foxglove::Trajectory> all;
    for (const auto& [id, path] : paths) all.push_back({id, {path.begin(), path.end()}});
    last_trajectories =
        std::make_shared<const std::string>(foxglove::trajectories("map", all, wallNowNs()));
    broadcast(kTrajectories, last_trajectories);
  }
  if (options.voxels && anyoneOn(kVoxels) && view->version() != voxel_version) {
    voxel_version = view->version();
    const std::uint32_t n = options.voxel_window_cells;
    last_voxels = std::make_shared<const std::string>(foxglove::voxelWindow(
        *view, robot, n, std::max<std::uint32_t>(n / 2, 8), "map", wallNowNs()));
    broadcast(kVoxels, last_voxels);
  }
}

void FoxgloveRoom::Impl::tick() {
  ticker.expires_after(std::chrono::milliseconds(100));
  ticker.async_wait([this](beast::error_code ec) {
    if (ec || !running.load()) return;
    guarded("foxglove", [&] {
      const auto now = Clock::now();
      const auto stall = std::chrono::duration_cast<Clock::duration>(
          std::chrono::duration<double>(options.stall_close_s));
      std::vector<std::shared_ptr<SessionBase>> stalled;
      for (auto& [id, s] : sessions) {
        if (s->writing && now - s->write_began > stall) stalled.push_back(s);
      }
      for (auto& s : stalled) remove(s, true);
      if (now >= next_period) {
        next_period = now + std::chrono::duration_cast<Clock::duration>(
                                std::chrono::duration<double>(options.grid_period_s));
        periodic();
      }
    });
    tick();
  });
}

// ---------------------------------------------------------------------------------------------
// FoxgloveRoom

Expected<std::unique_ptr<FoxgloveRoom>> FoxgloveRoom::create(const FoxgloveOptions& options,
                                                             std::shared_ptr<const MapView> view) {
  auto impl = std::make_unique<Impl>(options);
  impl->view = std::move(view);
  const std::string where = options.address + ":" + std::to_string(options.port);
  if (options.tls) {
    try {
      impl->tls.emplace(ssl::context::tls_server);
      impl->tls->set_options(ssl::context::default_workarounds | ssl::context::no_sslv2 |
                             ssl::context::no_sslv3 | ssl::context::no_tlsv1 |
                             ssl::context::no_tlsv1_1);
      impl->tls->use_certificate_chain_file(options.tls->certificate_chain);
      impl->tls->use_private_key_file(options.tls->private_key, ssl::context::pem);
    } catch (const std::exception& e) {
      return makeError("foxglove: TLS certificate or key: " + std::string(e.what()));
    }
  }
  beast::error_code ec;
  const auto address = net::ip::make_address(options.address, ec);
  if (ec) return makeError("foxglove.address '" + options.address + "': " + ec.message());
  const tcp::endpoint endpoint(address, options.port);
  impl->acceptor.open(endpoint.protocol(), ec);
  if (!ec) impl->acceptor.set_option(net::socket_base::reuse_address(true), ec);
  if (!ec) impl->acceptor.bind(endpoint, ec);
  if (!ec) impl->acceptor.listen(net::socket_base::max_listen_connections, ec);
  if (ec) return makeError("foxglove: cannot listen on " + where + ": " + ec.message());
  impl->server_info = foxglove::serverInfoJson(
      options.server_name, std::to_string(wallNowNs()),
      std::vector<std::pair<std::string, std::string>>{{"densemap", "occupancy map server"}});
  impl->advertise = foxglove::advertiseJson(impl->channels);
  return std::unique_ptr<FoxgloveRoom>(new FoxgloveRoom(std::move(impl)));
}

FoxgloveRoom::FoxgloveRoom(std::unique_ptr<Impl> impl) : impl_(std::move(impl)) {}

FoxgloveRoom::~FoxgloveRoom() { stop(); }

void FoxgloveRoom::start() {
  if (impl_->running.exchange(true)) return;
  impl_->acceptNext();
  impl_->tick();
  impl_->thread = std::thread([impl = impl_.get()] {
    // Viewers get the CPU the map leaves: this thread runs at a lower priority (Linux: a
    // thread's own nice value) than the pipeline's.
    (void)::setpriority(PRIO_PROCESS, static_cast<id_t>(::gettid()), kThreadNice);
    while (true) {
      bool done = false;
      guarded("foxglove", [&] {
        impl->ioc.run();
        done = true;
      });
      if (done) break;  // run() returned: stopped; else a handler threw and the loop goes on
    }
  });
  spdlog::info("Foxglove WebSocket endpoint on {}://{}:{}", impl_->tls ? "wss" : "ws",
               impl_->options.address, port());
}

void FoxgloveRoom::stop() {
  if (!impl_->running.exchange(false)) return;
  net::post(impl_->ioc, [impl = impl_.get()] {
    beast::error_code ec;
    impl->acceptor.close(ec);
    impl->ticker.cancel();
    auto sessions = impl->sessions;
    for (auto& [id, s] : sessions) impl->remove(s, false);
    impl->ioc.stop();
  });
  if (impl_->thread.joinable()) impl_->thread.join();
}

void FoxgloveRoom::onVersion(const IntegrationResult& result,
                             const std::shared_ptr<const MapView>& view) {
  impl_->handOver([&](Impl::Pending& p) {
    p.view = view;
    if (!p.all_blocks) {
      p.blocks.insert(p.blocks.end(), result.written_blocks.begin(), result.written_blocks.end());
      if (p.blocks.size() > kMaxPendingBlocks) {
        p.all_blocks = true;
        p.blocks = {};
      }
    }
    if (result.from_scan && result.points_world) {
      p.scan = result.points_world;
      p.scan_stamp_ns = result.stamp_ns;
      if (p.poses.size() < kMaxPendingPoses) {
        foxglove::Pose pose;
        pose.child = foxglove::sensorFrameId(result.sensor_id);
        const Eigen::Vector3d t = result.T_world_sensor.translation();
        const Eigen::Quaterniond q(result.T_world_sensor.rotation());
        pose.t[0] = t.x();
        pose.t[1] = t.y();
        pose.t[2] = t.z();
        pose.q[0] = q.x();
        pose.q[1] = q.y();
        pose.q[2] = q.z();
        pose.q[3] = q.w();
        pose.stamp_ns = result.stamp_ns != 0 ? result.stamp_ns : wallNowNs();
        p.poses.push_back(std::move(pose));
      }
    }
  });
}

void FoxgloveRoom::onStatus(const ServerStatus& status) {
  impl_->handOver([&](Impl::Pending& p) { p.status = status; });
}

FoxgloveRoom::Counters FoxgloveRoom::counters() const {
  return {impl_->n_clients.load(), impl_->n_dropped.load(), impl_->n_closed.load(),
          impl_->n_rejected.load()};
}

std::uint16_t FoxgloveRoom::port() const {
  beast::error_code ec;
  const auto endpoint = impl_->acceptor.local_endpoint(ec);
  return ec ? impl_->options.port : endpoint.port();
}

}  // namespace densemap::server
