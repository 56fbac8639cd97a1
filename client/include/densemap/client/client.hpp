#pragma once

#include <array>
#include <chrono>
#include <cstdint>
#include <functional>
#include <memory>
#include <optional>
#include <span>
#include <string>
#include <vector>

#include "densemap/client/map_snapshot.hpp"
#include "densemap/geometry/error.hpp"
#include "densemap/geometry/point_cloud.hpp"
#include "densemap/io/raw_scan.hpp"
#include "densemap/map/cell_change.hpp"
#include "densemap/planner/planner_types.hpp"
#include "densemap/query/cell_state.hpp"
#include "densemap/wire/security.hpp"
#include "densemap/wire/server_status.hpp"

namespace densemap {

struct ClientOptions {
  std::uint32_t domain_id = 0;
  std::string network_interface = "lo";
  std::chrono::milliseconds timeout{5000};  // per request, and for discovering the server
  /// Subscribe to map/delta (every changed cell of every version). Off by default: while no
  /// client subscribes, the server builds no deltas. map/events (small) is always read.
  bool subscribe_deltas = false;
  /// DDS Security files of this client's identity (scripts/make-pki.sh); none: plain DDS. With
  /// security, requests its permissions do not grant fail with a "not allowed" error. One
  /// identity per process and domain (Cyclone DDS): a Client with another is refused.
  std::optional<dds::SecurityFiles> security{};
  /// The server to ask among several on the domain (its dds.instance; docs/fleet.md). Empty:
  /// the domain's one server.
  std::string instance{};
  /// Replicas to fail over to, in order, after `instance`: a request that gets no reply within
  /// `timeout` is sent again to the next replica, which then serves every later call (scans
  /// reach all of them anyway). Their endpoints are made at create(), so the switch costs no
  /// discovery. Empty: no failover.
  std::vector<std::string> replicas{};
};

struct PointQueryAnswer {
  std::uint64_t map_version = 0;
  std::vector<std::optional<float>> log_odds;
  std::vector<CellState> states;
};

struct BoxQueryAnswer {
  std::uint64_t map_version = 0;
  std::uint64_t occupied = 0, free = 0, unknown = 0;
  std::vector<Point3f> occupied_centers;
};

struct RayQueryAnswer {
  std::uint64_t map_version = 0;
  RayQueryResult ray;
};

/// Distances from the server's distance field (config esdf; docs/planner.md).
struct DistanceQueryAnswer : DistanceQueryResult {
  std::uint64_t map_version = 0;
  float max_distance = 0.0F;  // distances are at most this (meaning none within it)
};

/// A swept-volume check of a path (or of oriented boxes) on the server's map.
struct PathQueryAnswer : SweptVolumeResult {
  std::uint64_t map_version = 0;
};

/// A dense box of the server's distance field: the distance (metres) of every cell from
/// `min_center` on, `size` cells an axis, x fastest, then y, then z.
struct DistanceBoxAnswer {
  std::uint64_t map_version = 0;
  float max_distance = 0.0F;
  Point3f min_center = Point3f::Zero();
  std::array<std::uint32_t, 3> size{};
  std::vector<float> distances;
};

struct DeltaInfo {
  std::uint64_t base_version = 0, new_version = 0;
  bool from_scan = false;
  std::string sensor_id;
  std::uint64_t scan_seq = 0;
  CellChanges changes;
};

/// One published map version (densemap/map/events).
struct MapEventInfo {
  std::uint64_t base_version = 0, new_version = 0;
  bool from_scan = false;
  std::string sensor_id;
  std::uint64_t scan_seq = 0;
  std::uint64_t changed_cells = 0;
  std::uint32_t written_blocks = 0;
  double latency_ms = 0.0;  // the server's receive -> published
};

/// The server's map/manifest: its latest version and, for a spatial shard (map.bounds), the
/// box whose blocks (by their centre) it keeps.
struct MapManifestInfo {
  std::uint64_t version = 0;
  double resolution = 0.0;
  std::uint64_t known_cells = 0;
  std::optional<std::pair<Point3f, Point3f>> bounds;  // none: all of space
};

struct ClientAccess;

/// A densemap-server client over DDS (loopback by default). Requests carry a random client id
/// and an increasing request id; replies are matched on both. Every call has a timeout.
/// Thread-safety: one thread at a time (each thread may have a Client of its own).
class Client {
 public:
  [[nodiscard]] static Expected<std::unique_ptr<Client>> create(const ClientOptions& options);
  ~Client();
  Client(const Client&) = delete;
  Client& operator=(const Client&) = delete;

  /// Waits until a server's scan reader and request readers are matched.
  [[nodiscard]] Expected<void> waitForServer();
  [[nodiscard]] Expected<void> publishScan(const RawScan& scan);
  /// Publishes new poses for past scans of one sensor (densemap/pose_correction): every server
  /// with a history (config history) on the domain re-integrates them (docs/fleet.md). An error
  /// for more than kMaxCorrectedPoses poses; the server counts what it refuses in its status.
  [[nodiscard]] Expected<void> publishPoseCorrection(const PoseCorrection& correction);
  /// The cells at the points (metres, world frame). A batch of more than 250,000 points goes as
  /// several requests, one after another, each answered from one map version; map_version is
  /// then the last part's.
  [[nodiscard]] Expected<PointQueryAnswer> queryPoints(const std::vector<Point3f>& points_world);
  /// The same for coordinates x y z per point (an error unless their count is a multiple of 3).
  [[nodiscard]] Expected<PointQueryAnswer> queryPoints(std::span<const float> xyz_world);
  [[nodiscard]] Expected<BoxQueryAnswer> queryBox(const Point3f& min, const Point3f& max,
                                                  std::uint32_t max_centers = 0);
  [[nodiscard]] Expected<RayQueryAnswer> castRay(const Point3f& origin, const Point3f& direction,
                                                 float max_range);
  /// Distances (with gradients and nearest obstacles) at the points x y z (metres, world
  /// frame) from the server's distance field; an error when the server keeps none. A batch of
  /// more than 250,000 points goes as several requests, as queryPoints does.
  [[nodiscard]] Expected<DistanceQueryAnswer> queryDistances(
      std::span<const float> xyz_world, const DistanceQueryOptions& options = {});
  /// Whether a robot of radius `radius_m` can follow the polyline `vertices_world` (x y z per
  /// vertex, at most 100,000): every cell within the radius of the path counts.
  [[nodiscard]] Expected<PathQueryAnswer> checkPath(std::span<const float> vertices_world,
                                                    double radius_m);
  /// Whether oriented boxes (a footprint at poses along a trajectory, at most 100,000) are
  /// free: every cell a box touches counts; the conflict's index is the box.
  [[nodiscard]] Expected<PathQueryAnswer> checkBoxes(std::span<const OrientedBox> boxes);
  /// The server's distance field over the box [min, max] (metres) as a dense array, at most
  /// 4,194,304 cells (and the server's request budget).
  [[nodiscard]] Expected<DistanceBoxAnswer> distanceBox(const Point3f& min, const Point3f& max,
                                                        bool unknown_as_occupied = false);
  /// Clears the whole map (a new, empty version). Returns the server's detail message.
  [[nodiscard]] Expected<std::string> reset();
  /// Forgets the cells of the box [min, max] (metres, world frame): they become unknown.
  [[nodiscard]] Expected<std::string> clearBox(const Point3f& min, const Point3f& max);
  /// Has the server save its snapshot (`name` empty: its configured snapshot, with its
  /// generations) or write `name` (a plain file name ending .dmap, .bt or .ot, never a path)
  /// into its export directory.
  [[nodiscard]] Expected<std::string> save(const std::string& name = {});
  /// The latest status sample (published at 1 Hz, transient-local).
  [[nodiscard]] Expected<ServerStatus> status();
  /// Calls `f` for every map delta received since the last call; returns how many. Needs
  /// ClientOptions::subscribe_deltas (otherwise returns 0).
  std::size_t pollDeltas(const std::function<void(const DeltaInfo&)>& f);
  /// Calls `f` for every map event received since the last call; returns how many.
  std::size_t pollEvents(const std::function<void(const MapEventInfo&)>& f);
  /// The server's latest manifest (published at 1 Hz, transient-local); waits for the first
  /// up to the timeout.
  [[nodiscard]] Expected<MapManifestInfo> manifest();
  /// Fetches the server's map (what a late joiner does): waits until the manifest reaches
  /// `min_version`, asks for the map (send-map) and rebuilds it from the tiles of one version.
  /// Times out only when tiles stop arriving.
  [[nodiscard]] Expected<MapSnapshot> fetchMap(std::uint64_t min_version = 0);

 private:
  friend struct ClientAccess;
  struct Impl;
  explicit Client(std::vector<std::unique_ptr<Impl>> replicas);
  /// Runs `ask` on the replica in use; while it goes unanswered, on the next ones in turn.
  template <class F>
  auto failingOver(F&& ask) -> decltype(ask(std::declval<Impl&>()));
  std::unique_ptr<Impl> impl_;                   // the server in use
  std::vector<std::unique_ptr<Impl>> standby_;  // the replicas after it, in order
};

}  // namespace densemap
