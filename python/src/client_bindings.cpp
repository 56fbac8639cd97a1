// densemap.Client: a running densemap-server's map over DDS (densemap/client/client.hpp).
#include <pybind11/stl.h>
#include <pybind11/stl/filesystem.h>

#include <chrono>
#include <cmath>
#include <filesystem>
#include <limits>
#include <memory>

#include "bindings.hpp"
#include "densemap/client/client.hpp"
#include "densemap/client/sharded_client.hpp"
#include "densemap/geometry/rigid_transform.hpp"
#include "densemap/io/scan.hpp"
#include "densemap/mapper/mapper.hpp"

namespace densemap::python {
namespace {

/// A client's options from Python's arguments (the timeout in seconds, checked).
ClientOptions clientOptions(std::uint32_t domain_id, double timeout_s,
                            const std::string& network_interface, const std::string& instance) {
  if (!(timeout_s > 0 && timeout_s <= 3600)) {
    throw py::value_error("timeout must be in (0, 3600] s");
  }
  ClientOptions o;
  o.domain_id = domain_id;
  o.network_interface = network_interface;
  o.timeout = std::chrono::milliseconds(static_cast<long>(timeout_s * 1000));
  o.instance = instance;
  return o;
}

/// A Client that can be closed: every call on a closed one raises densemap.Error.
class PyClient {
 public:
  PyClient(std::uint32_t domain_id, double timeout_s, const std::string& network_interface,
           const std::string& instance, const std::vector<std::string>& replicas) {
    ClientOptions o = clientOptions(domain_id, timeout_s, network_interface, instance);
    o.replicas = replicas;
    client_ = valueOrRaise(Client::create(o));
  }

  Client& client() {
    if (!client_) throw DensemapError("the client is closed");
    return *client_;
  }
  void close() { client_.reset(); }

 private:
  std::unique_ptr<Client> client_;
};

/// A ShardedClient that can be closed, as PyClient.
class PyShardedClient {
 public:
  PyShardedClient(const std::vector<std::uint32_t>& domain_ids, double timeout_s,
                  const std::string& network_interface, const std::vector<std::string>& instances) {
    if (domain_ids.empty() || domain_ids.size() > ShardedClient::kMaxShards) {
      throw py::value_error("domain_ids: 1 .. " + std::to_string(ShardedClient::kMaxShards) +
                            " shards");
    }
    if (!instances.empty() && instances.size() != domain_ids.size()) {
      throw py::value_error("instances: one per shard, as domain_ids");
    }
    std::vector<ClientOptions> shards;
    for (std::size_t i = 0; i < domain_ids.size(); ++i) {
      shards.push_back(clientOptions(domain_ids[i], timeout_s, network_interface,
                                     instances.empty() ? std::string() : instances[i]));
    }
    client_ = valueOrRaise(ShardedClient::create(shards));
  }

  ShardedClient& client() {
    if (!client_) throw DensemapError("the client is closed");
    return *client_;
  }
  void close() { client_.reset(); }

 private:
  std::unique_ptr<ShardedClient> client_;
};

py::dict statusDict(const ServerStatus& s) {
  py::dict d;
  d["map_version"] = s.map_version;
  d["known_cells"] = s.known_cells;
  d["memory_bytes"] = s.memory_bytes;
  d["received"] = s.received;
  d["integrated"] = s.integrated;
  d["dropped"] = s.dropped;
  d["rejected"] = s.rejected;
  d["last_reject_reason"] = s.last_reject_reason;
  d["latency_p50_ms"] = s.latency_p50_ms;
  d["latency_p99_ms"] = s.latency_p99_ms;
  d["uptime_s"] = s.uptime_s;
  d["cpu_s"] = s.cpu_s;
  d["rss_bytes"] = s.rss_bytes;
  d["queries_answered"] = s.queries_answered;
  d["queries_rejected"] = s.queries_rejected;
  py::list sensors;
  for (const SensorCounters& c : s.sensors) {
    py::dict sensor;
    sensor["sensor_id"] = c.sensor_id;
    sensor["received"] = c.received;
    sensor["integrated"] = c.integrated;
    sensor["dropped"] = c.dropped;
    sensor["rejected"] = c.rejected;
    sensor["seq_gaps"] = c.seq_gaps;
    sensor["latency_p50_ms"] = c.latency_p50_ms;
    sensor["latency_p99_ms"] = c.latency_p99_ms;
    sensors.append(sensor);
  }
  d["sensors"] = sensors;
  const HistoryStatus& h = s.history;
  py::dict history;
  history["enabled"] = h.enabled;
  history["scans"] = h.scans;
  history["bytes"] = h.bytes;
  history["corrections"] = h.corrections;
  history["corrections_rejected"] = h.corrections_rejected;
  history["corrected_scans"] = h.corrected_scans;
  history["unmatched_poses"] = h.unmatched_poses;
  history["reintegrating"] = h.reintegrating;
  history["reintegration_done"] = h.reintegration_done;
  history["reintegration_total"] = h.reintegration_total;
  history["reintegrations"] = h.reintegrations;
  history["last_ms_per_scan"] = h.last_ms_per_scan;
  history["last_version"] = h.last_version;
  history["last_error"] = h.last_error;
  d["history"] = history;
  return d;
}

/// (log-odds float32 with NaN where unknown, states uint8) of an answer.
py::tuple answerArrays(const PointQueryAnswer& a) {
  const auto n = static_cast<py::ssize_t>(a.states.size());
  py::array_t<float> log_odds(n);
  py::array_t<std::uint8_t> states(n);
  for (py::ssize_t i = 0; i < n; ++i) {
    log_odds.mutable_data()[i] =
        a.log_odds[i] ? *a.log_odds[i] : std::numeric_limits<float>::quiet_NaN();
    states.mutable_data()[i] = static_cast<std::uint8_t>(a.states[i]);
  }
  return py::make_tuple(a.map_version, states, log_odds);
}

/// A box query's answer as Client.query_box returns it.
py::dict boxDict(const BoxQueryAnswer& a) {
  py::dict d = countsDict(a);
  d["map_version"] = a.map_version;
  d["occupied_centers"] =
      pointsArray(PointCloud(a.occupied_centers.begin(), a.occupied_centers.end()));
  return d;
}

/// A ray's answer as Client.cast_ray returns it.
py::dict rayDict(const RayQueryAnswer& a) {
  py::dict d;
  d["map_version"] = a.map_version;
  d["hit"] = a.ray.hit;
  d["center"] = py::make_tuple(a.ray.hit_center.x(), a.ray.hit_center.y(), a.ray.hit_center.z());
  d["distance"] = a.ray.distance;
  return d;
}

}  // namespace

void bindClient(py::module_& m) {
  py::class_<MapSnapshot>(m, "MapSnapshot",
                          "A server's map at one version, copied into this process "
                          "(Client.fetch_map). Read-only; thread-safe.")
      .def_property_readonly("version", &MapSnapshot::version, "The server's map version.")
      .def_property_readonly("resolution", &MapSnapshot::resolution, "Voxel edge, m.")
      .def_property_readonly("known_cells", &MapSnapshot::knownCells, "Cells known.")
      .def(
          "cells",
          [](const MapSnapshot& self) {
            PointCloud centres;
            std::vector<float> values;
            self.forEachCell([&](const Point3f& c, float v) {
              centres.push_back(c);
              values.push_back(v);
            });
            py::array_t<float> v(static_cast<py::ssize_t>(values.size()));
            std::copy(values.begin(), values.end(), v.mutable_data());
            return py::make_tuple(pointsArray(centres), v);
          },
          "(centres float32 (M, 3), log_odds float32 (M,)) of every known cell.")
      .def(
          "save",
          [](const MapSnapshot& self, const std::filesystem::path& path) {
            py::gil_scoped_release release;
            return valueOrRaise(self.save(path.string()));
          },
          py::arg("path"), "Writes .dmap, .bt or .ot; returns the bytes written.");

  py::class_<PyClient>(m, "Client", R"doc(
A client of a running densemap-server over DDS (loopback by default). Every call has a
timeout and raises densemap.Error on it, on a refusal (with the server's message) and on a
closed client. The GIL is released while a call waits. Use as a context manager, or close().
instance names the server among replicas on the domain (its dds.instance); a query the
server in use leaves unanswered goes to the next of `replicas`, which serves from then on.
)doc")
      .def(py::init<std::uint32_t, double, const std::string&, const std::string&,
                    const std::vector<std::string>&>(),
           py::kw_only(), py::arg("domain_id") = 0, py::arg("timeout") = 5.0,
           py::arg("network_interface") = "lo", py::arg("instance") = "",
           py::arg("replicas") = std::vector<std::string>{})
      .def(
          "wait_for_server",
          [](PyClient& self) {
            Client& c = self.client();
            py::gil_scoped_release release;
            valueOrRaise(c.waitForServer());
          },
          "Waits until a server's readers are matched (raises densemap.Error on timeout).")
      .def(
          "query_points",
          [](PyClient& self, const py::handle& points) {
            const PointCloud cloud =
                pointsFrom(points, std::numeric_limits<std::size_t>::max(), "points", false);
            Client& c = self.client();
            const PointQueryAnswer a = released([&] { return c.queryPoints(cloud); });
            return answerArrays(a);
          },
          py::arg("points"),
          "(map_version, states uint8 (N,), log_odds float32 (N,), NaN where unknown).")
      .def(
          "query_box",
          [](PyClient& self, const py::handle& box_min, const py::handle& box_max,
             std::uint32_t max_centers) {
            const Point3f lo = pointFrom(box_min, "box_min"), hi = pointFrom(box_max, "box_max");
            Client& c = self.client();
            return boxDict(released([&] { return c.queryBox(lo, hi, max_centers); }));
          },
          py::arg("box_min"), py::arg("box_max"), py::arg("max_centers") = 0,
          "Counts of the box's cells by state, and up to max_centers occupied centres.")
      .def(
          "cast_ray",
          [](PyClient& self, const py::handle& origin, const py::handle& direction,
             float max_range) {
            const Point3f o = pointFrom(origin, "origin"), dir = pointFrom(direction, "direction");
            Client& c = self.client();
            return rayDict(released([&] { return c.castRay(o, dir, max_range); }));
          },
          py::arg("origin"), py::arg("direction"), py::arg("max_range"),
          "The first occupied cell along the ray: {'map_version', 'hit', 'center', 'distance'}.")
      .def(
          "query_distances",
          [](PyClient& self, const py::handle& points, bool unknown_as_occupied, bool interpolate,
             bool nearest) {
            const PointCloud cloud =
                pointsFrom(points, std::numeric_limits<std::size_t>::max(), "points", false);
            const std::span<const float> xyz(cloud.empty() ? nullptr : cloud.front().data(),
                                             cloud.size() * 3);
            Client& c = self.client();
            const DistanceQueryAnswer a = released([&] {
              return c.queryDistances(xyz, {.unknown_as_occupied = unknown_as_occupied,
                                            .interpolate = interpolate,
                                            .nearest = nearest});
            });
            return py::make_tuple(a.map_version) + distanceArrays(a);
          },
          py::arg("points"), py::kw_only(), py::arg("unknown_as_occupied") = false,
          py::arg("interpolate") = false, py::arg("nearest") = true,
          "(map_version, distances, gradients, nearest) from the server's distance field, as "
          "Mapper.distance answers (the server needs esdf { enabled: true }).")
      .def(
          "check_path",
          [](PyClient& self, const py::handle& vertices, double radius) {
            const PointCloud path =
                pointsFrom(vertices, std::numeric_limits<std::size_t>::max(), "vertices", false);
            const std::span<const float> xyz(path.empty() ? nullptr : path.front().data(),
                                             path.size() * 3);
            Client& c = self.client();
            const PathQueryAnswer a = released([&] { return c.checkPath(xyz, radius); });
            py::dict d = sweptDict(a, "segment");
            d["map_version"] = a.map_version;
            return d;
          },
          py::arg("vertices"), py::arg("radius"),
          "The server's answer to Mapper.check_path's question, with its 'map_version'.")
      .def(
          "check_boxes",
          [](PyClient& self, const py::handle& centers, const py::handle& half_extents,
             const py::handle& rotations) {
            const std::vector<OrientedBox> boxes = boxesFrom(centers, half_extents, rotations);
            Client& c = self.client();
            const PathQueryAnswer a = released([&] { return c.checkBoxes(boxes); });
            py::dict d = sweptDict(a, "box");
            d["map_version"] = a.map_version;
            return d;
          },
          py::arg("centers"), py::arg("half_extents"), py::arg("rotations"),
          "The server's answer to Mapper.check_boxes's question, with its 'map_version'.")
      .def(
          "distance_box",
          [](PyClient& self, const py::handle& box_min, const py::handle& box_max,
             bool unknown_as_occupied) {
            const Point3f lo = pointFrom(box_min, "box_min"), hi = pointFrom(box_max, "box_max");
            Client& c = self.client();
            const DistanceBoxAnswer a =
                released([&] { return c.distanceBox(lo, hi, unknown_as_occupied); });
            return distanceGrid(a.size, a.distances, a.min_center);
          },
          py::arg("box_min"), py::arg("box_max"), py::kw_only(),
          py::arg("unknown_as_occupied") = false,
          R"doc(The server's distance field over the box, as Mapper.distance_box gives it (at
most 4,194,304 cells; the server needs esdf { enabled: true }).)doc")
      .def(
          "status",
          [](PyClient& self) {
            Client& c = self.client();
            const ServerStatus s = released([&] { return c.status(); });
            return statusDict(s);
          },
          "The server's latest status sample (a dict).")
      .def(
          "fetch_map",
          [](PyClient& self, std::uint64_t min_version) {
            Client& c = self.client();
            py::gil_scoped_release release;
            return valueOrRaise(c.fetchMap(min_version));
          },
          py::arg("min_version") = 0, "The server's map (a MapSnapshot) at min_version or later.")
      .def(
          "publish_scan",
          [](PyClient& self, const py::handle& points, const py::handle& T_world_sensor,
             const std::string& sensor_id, std::uint64_t seq, std::int64_t stamp_ns) {
            const PointCloud cloud =
                pointsFrom(points, MapperOptions{}.max_points, "points_sensor", false);
            const Eigen::Isometry3d pose = poseFrom(T_world_sensor, "T_world_sensor");
            valueOrRaise(checkRigidPose(pose));
            Scan scan;
            scan.frame = PointFrame::kSensor;
            scan.T_world_sensor = pose;
            scan.points = cloud;
            RawScan raw = toRawScan(scan, seq, sensor_id);
            if (stamp_ns != 0) raw.stamp_ns = stamp_ns;
            Client& c = self.client();
            py::gil_scoped_release release;
            valueOrRaise(c.publishScan(raw));
          },
          py::arg("points_sensor"), py::arg("T_world_sensor"), py::arg("sensor_id") = "python",
          py::arg("seq") = 0, py::arg("stamp_ns") = 0,
          "Sends one sensor-frame scan with its pose (4x4) to the server (stamp_ns 0: now).")
      .def(
          "publish_pose_correction",
          [](PyClient& self, const std::string& sensor_id, const py::sequence& poses) {
            const std::size_t n = py::len(poses);
            if (n > kMaxCorrectedPoses) {
              throw py::value_error("a pose correction carries at most " +
                                    std::to_string(kMaxCorrectedPoses) + " poses, not " +
                                    std::to_string(n));
            }
            PoseCorrection correction{.sensor_id = sensor_id};
            correction.poses.reserve(n);
            for (std::size_t i = 0; i < n; ++i) {
              const std::string what = "poses[" + std::to_string(i) + "]";
              const py::object item = poses[i];
              if (!py::isinstance<py::sequence>(item) || py::len(item) != 2) {
                throw py::type_error(what + " must be a (stamp_ns, T_world_sensor) pair");
              }
              const auto pair = item.cast<py::sequence>();
              const auto stamp_ns = pair[0].cast<std::int64_t>();
              const Eigen::Isometry3d pose = poseFrom(pair[1], what + " T_world_sensor");
              valueOrRaise(checkRigidPose(pose));
              correction.poses.push_back(toCorrectedPose(stamp_ns, pose));
            }
            Client& c = self.client();
            py::gil_scoped_release release;
            valueOrRaise(c.publishPoseCorrection(correction));
          },
          py::arg("sensor_id"), py::arg("poses"),
          R"doc(Sends new poses for past scans of one sensor: poses is a sequence of
(stamp_ns, T_world_sensor 4x4) pairs, each naming the scan with that stamp. A server with a
history (config history) re-integrates them; status()["history"] shows its progress.)doc")
      .def(
          "publish",
          [](PyClient& self, const Scan& scan, const std::string& sensor_id, std::uint64_t seq) {
            RawScan raw = toRawScan(scan, seq, sensor_id);
            if (scan.stamp_ns) raw.stamp_ns = *scan.stamp_ns;
            Client& c = self.client();
            py::gil_scoped_release release;
            valueOrRaise(c.publishScan(raw));
          },
          py::arg("scan"), py::arg("sensor_id") = "python", py::arg("seq") = 0,
          "Sends a Scan of densemap.read_scans to the server (in its sensor frame).")
      .def(
          "reset",
          [](PyClient& self) {
            Client& c = self.client();
            py::gil_scoped_release release;
            return valueOrRaise(c.reset());
          },
          "Clears the server's map; returns its message.")
      .def(
          "clear_box",
          [](PyClient& self, const py::handle& box_min, const py::handle& box_max) {
            const Point3f lo = pointFrom(box_min, "box_min"), hi = pointFrom(box_max, "box_max");
            Client& c = self.client();
            py::gil_scoped_release release;
            return valueOrRaise(c.clearBox(lo, hi));
          },
          py::arg("box_min"), py::arg("box_max"), "Forgets the box's cells on the server.")
      .def(
          "save",
          [](PyClient& self, const std::string& name) {
            Client& c = self.client();
            py::gil_scoped_release release;
            return valueOrRaise(c.save(name));
          },
          py::arg("name") = "",
          "Has the server save its snapshot, or write `name` (.dmap, .bt, .ot; a file name, "
          "never a path) into its export directory.")
      .def("close", &PyClient::close, "Closes the client (its DDS participant).")
      .def("__enter__", [](PyClient& self) -> PyClient& { return self; })
      .def("__exit__", [](PyClient& self, const py::args&) { self.close(); });

  py::class_<PyShardedClient>(m, "ShardedClient", R"doc(
Queries over spatial shards: densemap-servers whose map.bounds tile space, each on its own DDS
domain or with its own dds.instance (domain_ids and instances: one per shard), answered as one map (docs/fleet.md). Each point goes to the shard that keeps its cell, a
box to every shard it may touch, a ray to every shard (the nearest hit wins); map_version is the
oldest among the shards that answered. Raises densemap.Error as Client does.
)doc")
      .def(py::init<const std::vector<std::uint32_t>&, double, const std::string&,
                    const std::vector<std::string>&>(),
           py::kw_only(), py::arg("domain_ids"), py::arg("timeout") = 5.0,
           py::arg("network_interface") = "lo", py::arg("instances") = std::vector<std::string>{})
      .def_property_readonly(
          "shards", [](PyShardedClient& self) { return self.client().shards(); },
          "How many shards.")
      .def(
          "owner_of",
          [](PyShardedClient& self, const py::handle& point) -> std::optional<std::size_t> {
            return self.client().ownerOf(pointFrom(point, "point"));
          },
          py::arg("point"), "The index of the shard that keeps the cell at the point, or None.")
      .def(
          "query_points",
          [](PyShardedClient& self, const py::handle& points) {
            const PointCloud cloud =
                pointsFrom(points, std::numeric_limits<std::size_t>::max(), "points", false);
            const std::span<const float> xyz(cloud.empty() ? nullptr : cloud.front().data(),
                                             cloud.size() * 3);
            ShardedClient& c = self.client();
            const PointQueryAnswer a = released([&] { return c.queryPoints(xyz); });
            return answerArrays(a);
          },
          py::arg("points"), "As Client.query_points, over all shards.")
      .def(
          "query_box",
          [](PyShardedClient& self, const py::handle& box_min, const py::handle& box_max,
             std::uint32_t max_centers) {
            const Point3f lo = pointFrom(box_min, "box_min"), hi = pointFrom(box_max, "box_max");
            ShardedClient& c = self.client();
            return boxDict(released([&] { return c.queryBox(lo, hi, max_centers); }));
          },
          py::arg("box_min"), py::arg("box_max"), py::arg("max_centers") = 0,
          "As Client.query_box, over all shards.")
      .def(
          "cast_ray",
          [](PyShardedClient& self, const py::handle& origin, const py::handle& direction,
             float max_range) {
            const Point3f o = pointFrom(origin, "origin"), dir = pointFrom(direction, "direction");
            ShardedClient& c = self.client();
            return rayDict(released([&] { return c.castRay(o, dir, max_range); }));
          },
          py::arg("origin"), py::arg("direction"), py::arg("max_range"),
          "As Client.cast_ray, over all shards.")
      .def("close", &PyShardedClient::close, "Closes every shard's client.")
      .def("__enter__", [](PyShardedClient& self) -> PyShardedClient& { return self; })
      .def("__exit__", [](PyShardedClient& self, const py::args&) { self.close(); });
}

}  // namespace densemap::python
