#include "replay_command.hpp"

#include <sys/resource.h>

#include <atomic>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <map>
#include <thread>
#include <vector>

#include "cli_support.hpp"
#include "densemap/cli/progress.hpp"
#include "densemap/geometry/percentile.hpp"
#include "densemap/io/scan_source.hpp"
#include "densemap/ros2/recording.hpp"
#include "densemap/upsample/interpolation.hpp"

namespace densemap::cli {
namespace {

using Clock = std::chrono::steady_clock;

double msSince(Clock::time_point t0) {
  return std::chrono::duration<double, std::milli>(Clock::now() - t0).count();
}

/// This process's CPU seconds (user + system) and minor page faults so far.
struct ProcessUsage {
  double cpu_s = 0.0;
  long minor_faults = 0;
  static ProcessUsage now() {
    rusage u{};
    getrusage(RUSAGE_SELF, &u);
    const auto seconds = [](const timeval& t) { return t.tv_sec + 1e-6 * t.tv_usec; };
    return {seconds(u.ru_utime) + seconds(u.ru_stime), u.ru_minflt};
  }
};

/// --query-bbox-edge: a second client asks for bbox queries (cubes of that edge around the
/// latest sensor position) back to back, for as long as the replay sends scans.
class BboxLoad {
 public:
  BboxLoad(const ClientOptions& o, double edge_m) : edge_m_(edge_m) {
    if (edge_m <= 0) return;
    thread_ = std::thread([this, o] { run(o); });
  }
  ~BboxLoad() { stop(); }
  BboxLoad(const BboxLoad&) = delete;
  BboxLoad& operator=(const BboxLoad&) = delete;

  void follow(const Point3f& c) { x_ = c.x(), y_ = c.y(), z_ = c.z(); }
  void stop() {
    running_ = false;
    if (thread_.joinable()) thread_.join();
  }
  void print() const {
    if (edge_m_ <= 0) return;
    std::printf(
        "replay: bbox queries (%.1f m cubes) alongside: %zu answered, %zu failed, round trip "
        "p50 %.1f ms, p99 %.1f ms\n",
        edge_m_, ms_.size(), failed_, percentile(ms_, 0.5), percentile(ms_, 0.99));
  }

 private:
  void run(const ClientOptions& o) {
    auto other = connect(o);
    if (!other) {
      std::fprintf(stderr, "densemap: bbox load: %s\n", other.error().message.c_str());
      return;
    }
    while (running_.load()) {
      const Point3f c(x_.load(), y_.load(), z_.load());
      const Point3f half = Point3f::Constant(static_cast<float>(edge_m_ / 2));
      const auto t0 = Clock::now();
      if ((*other)->queryBox(c - half, c + half)) {
        ms_.push_back(msSince(t0));
      } else {
        ++failed_;
      }
    }
  }

  double edge_m_;
  std::atomic<bool> running_{true};
  std::atomic<float> x_{0}, y_{0}, z_{0};
  std::vector<double> ms_;  // read after stop()
  std::size_t failed_ = 0;
  std::thread thread_;
};

/// One replay's state: what was sent when, what came back, the optional outputs.
class ReplayRun {
 public:
  ReplayRun(Client& client, const ClientOptions& o, std::size_t query_points, double bbox_edge_m)
      : client_(client), bbox_(o, bbox_edge_m), query_points_(query_points) {}
  ~ReplayRun() {
    if (csv_ != nullptr) std::fclose(csv_);
  }
  ReplayRun(const ReplayRun&) = delete;
  ReplayRun& operator=(const ReplayRun&) = delete;

  /// --csv: a row per integrated scan, with the map's size from the latest status (1 Hz).
  Expected<void> openCsv(const std::string& path, const Expected<ServerStatus>& before) {
    if (before) last_status_ = *before;
    if (path.empty()) return {};
    csv_ = std::fopen(path.c_str(), "w");
    if (csv_ == nullptr) return makeError("cannot write " + path);
    std::fprintf(csv_,
                 "scan,server_ms,end_to_end_ms,changed_cells,written_blocks,known_cells,"
                 "map_bytes\n");
    return {};
  }

  /// Sends `raw` (through `ros` when given) at its slot, watching events while it waits.
  Expected<void> send(const RawScan& raw, Clock::time_point slot, RosReplayPublisher* ros,
                      std::size_t index) {
    while (Clock::now() < slot) {
      collect();
      std::this_thread::sleep_for(std::chrono::microseconds(500));
    }
    sent_at_[raw.seq] = Clock::now();
    return ros != nullptr ? ros->publish(raw, index) : client_.publishScan(raw);
  }

  /// After a scan: the query load around the sensor, then the events so far.
  void afterScan(const Point3f& sensor) {
    bbox_.follow(sensor);
    if (query_points_ > 0) queryAround(sensor);
    collect();
  }

  /// Waits for the last events: until every scan is seen or nothing new for 3 s.
  void drain() {
    auto last_news = Clock::now();
    while (!sent_at_.empty() && Clock::now() - last_news < std::chrono::seconds(3)) {
      const std::size_t had = latencies_.size();
      collect();
      if (latencies_.size() != had) last_news = Clock::now();
      std::this_thread::sleep_for(std::chrono::milliseconds(20));
    }
    bbox_.stop();
    if (csv_ != nullptr) std::fclose(csv_);
    csv_ = nullptr;
  }

  [[nodiscard]] std::size_t integrated() const { return latencies_.size(); }

  void printLatencies() const {
    std::printf(
        "replay: end-to-end latency (publish -> map event seen) over %zu scans: p50 %.1f ms, "
        "p99 %.1f ms\n",
        latencies_.size(), percentile(latencies_, 0.5), percentile(latencies_, 0.99));
    if (queried_ > 0) {
      std::printf(
          "replay: point queries while ingesting: %zu points in %.3f s of requests, %.3g "
          "points/s (round trip)\n",
          queried_, query_seconds_, static_cast<double>(queried_) / query_seconds_);
      std::printf(
          "replay: point-query round trip over %zu batches of %zu: p50 %.1f ms, p99 %.1f ms\n",
          point_ms_.size(), query_points_, percentile(point_ms_, 0.5), percentile(point_ms_, 0.99));
    }
    bbox_.print();
  }

 private:
  void collect() {
    if (csv_ != nullptr && Clock::now() >= next_status_) {
      if (auto s = client_.status(); s) last_status_ = *s;
      next_status_ = Clock::now() + std::chrono::seconds(1);
    }
    client_.pollEvents([&](const MapEventInfo& d) {
      const auto it = sent_at_.find(d.scan_seq);
      if (!d.from_scan || it == sent_at_.end()) return;
      latencies_.push_back(msSince(it->second));
      sent_at_.erase(it);
      if (csv_ == nullptr) return;
      std::fprintf(csv_, "%llu,%.3f,%.3f,%llu,%u,%llu,%llu\n",
                   static_cast<unsigned long long>(d.scan_seq - 1), d.latency_ms, latencies_.back(),
                   static_cast<unsigned long long>(d.changed_cells), d.written_blocks,
                   static_cast<unsigned long long>(last_status_.known_cells),
                   static_cast<unsigned long long>(last_status_.memory_bytes));
    });
  }

  /// --query-points: points around the sensor (a fixed spiral), one request.
  void queryAround(const Point3f& c) {
    std::vector<Point3f> probe;
    for (std::size_t k = 0; k < query_points_; ++k) {
      const float a = 0.618034F * static_cast<float>(k),
                  r = 20.0F * static_cast<float>(k % 97) / 97.0F;
      probe.emplace_back(c.x() + r * std::cos(a), c.y() + r * std::sin(a),
                         c.z() - 1.0F + static_cast<float>(k % 7) * 0.4F);
    }
    const auto t0 = Clock::now();
    if (client_.queryPoints(probe)) {
      query_seconds_ += msSince(t0) / 1000.0;
      point_ms_.push_back(msSince(t0));
      queried_ += probe.size();
    }
  }

  Client& client_;
  BboxLoad bbox_;
  std::size_t query_points_;
  std::FILE* csv_ = nullptr;
  ServerStatus last_status_;
  Clock::time_point next_status_ = Clock::now() + std::chrono::seconds(1);
  std::map<std::uint64_t, Clock::time_point> sent_at_;
  std::vector<double> latencies_;
  std::size_t queried_ = 0;
  double query_seconds_ = 0.0;
  std::vector<double> point_ms_;  // round trip of each point-query batch
};

/// --ros: a ROS 2 robot's publisher, once the server's face is known to be on and listening.
Expected<std::unique_ptr<RosReplayPublisher>> rosPublisher(const ClientOptions& o,
                                                           const std::string& ns,
                                                           const std::string& topic,
                                                           ros2::ReplayFrames frames, bool reliable,
                                                           double rate, double static_delay_s,
                                                           const Expected<ServerStatus>& s) {
  if (s && !s->ros_enabled) {
    return makeError("--ros: the server's ROS 2 face is off (config: ros2 { enabled: true })");
  }
  if (frames.stamp_base_ns == 0) {
    frames.stamp_base_ns = std::chrono::duration_cast<std::chrono::nanoseconds>(
                               std::chrono::system_clock::now().time_since_epoch())
                               .count();
  }
  if (rate > 0) frames.period_ns = static_cast<std::int64_t>(1e9 / rate);
  auto p = RosReplayPublisher::create(
      {o.domain_id, o.network_interface, o.security}, ns, topic, frames, reliable,
      std::chrono::milliseconds(static_cast<std::int64_t>(static_delay_s * 1000)));
  if (!p) return std::unexpected(p.error());
  if (auto ok = (*p)->waitForReader(static_cast<int>(o.timeout.count())); !ok) {
    return std::unexpected(ok.error());
  }
  return p;
}

/// The server's counts over the replay (its status before and after).
void printServerCounts(const Expected<ServerStatus>& before, const Expected<ServerStatus>& after) {
  if (!before || !after) return;
  std::printf("replay: server integrated %llu, dropped %llu, rejected %llu (last reason: %s)\n",
              static_cast<unsigned long long>(after->integrated - before->integrated),
              static_cast<unsigned long long>(after->dropped - before->dropped),
              static_cast<unsigned long long>(after->rejected - before->rejected),
              after->last_reject_reason.empty() ? "-" : after->last_reject_reason.c_str());
  std::printf("replay: server-side latency (receive -> published) p50 %.1f ms, p99 %.1f ms\n",
              after->latency_p50_ms, after->latency_p99_ms);
}

}  // namespace

ReplayCommand::ReplayCommand(CLI::App& app)
    : command_(app.add_subcommand("replay", "Publish a dataset's scans to the server")) {
  CLI::App& c = *command_;
  c.add_option("--data", data_, "Dataset (any format densemap reads, a ROS 2 .mcap bag too)")
      ->required();
  c.add_option("--rate", rate_, "Scans per second (0: as fast as possible)")->capture_default_str();
  c.add_flag("--recorded-rate", recorded_rate_,
             "Send each scan when its stamp says, relative to the first (a ROS 2 bag's clouds, "
             "as recorded), instead of --rate");
  c.add_option("--first", first_, "Skip this many scans")->capture_default_str();
  c.add_option("--query-bbox-edge", bbox_edge_m_,
               "While replaying, a second client sends bbox queries back to back: cubes of "
               "this edge (m) around the latest sensor position (0: none)")
      ->check(CLI::Range(0.0, 1000.0));
  c.add_option("--csv", csv_,
               "Write a row per integrated scan: scan, server and end-to-end latency (ms), "
               "changed cells, written blocks, known cells and map bytes (latest status)");
  c.add_option("--limit", limit_, "At most this many scans (0: all)")->capture_default_str();
  c.add_option("--query-points", query_points_,
               "After each scan, query this many points near the sensor (load test)")
      ->capture_default_str();
  c.add_option("--upsample", upsample_method_,
               "Densify each scan before sending: bilinear, nearest or iln")
      ->check(CLI::IsMember({"bilinear", "nearest", "iln"}));
  c.add_option("--upsample-model", upsample_model_, "ILN weights file (--upsample iln)")
      ->capture_default_str();
  c.add_option("--upsample-input", upsample_input_, "The sensor's grid ROWSxCOLS")
      ->capture_default_str();
  c.add_option("--upsample-output", upsample_output_, "The grid sent, ROWSxCOLS")
      ->capture_default_str();
  c.add_option("--fov-top", fov_top_, "The sensor's top beam, deg")->capture_default_str();
  c.add_option("--fov-bottom", fov_bottom_, "Its bottom beam, deg")->capture_default_str();
  c.add_flag("--ros", ros_,
             "Publish as a ROS 2 robot: sensor_msgs/PointCloud2 on --ros-topic and TF "
             "(map -> odom static, odom -> base_link per scan, base_link -> lidar static) "
             "on rt/tf and rt/tf_static; the server needs ros2 { enabled: true }");
  c.add_option("--ros-topic", ros_topic_, "ROS topic of the clouds")->capture_default_str();
  c.add_option("--ros-namespace", ros_namespace_,
               "Publish as the robot of this namespace (e.g. /robot1): the clouds on "
               "NS/--ros-topic and TF on NS/tf and NS/tf_static, as a server with "
               "ros2.robots reads them");
  c.add_option("--sensor-id", sensor_id_,
               "Without --ros: the scans' sensor id, what the server counts them under "
               "(at most 256 bytes)")
      ->capture_default_str();
  c.add_option("--ros-stamp-offset", ros_frames_.stamp_offset,
               "Stamp each cloud this fraction of a scan period after its pose's TF sample "
               "(0.5: the server interpolates between two samples and waits for the next)")
      ->check(CLI::Range(0.0, 0.99))
      ->capture_default_str();
  c.add_option("--ros-stamp-base-ns", ros_frames_.stamp_base_ns,
               "Stamp of the first scan, ns (0: now); the next are 1/rate apart")
      ->capture_default_str();
  c.add_option("--ros-static-delay", ros_static_delay_s_,
               "Publish /tf_static this many seconds after the first scans, as a late static "
               "broadcaster would (the server keeps waiting clouds for ros2.tf_wait_s)")
      ->check(CLI::Range(0.0, 60.0))
      ->capture_default_str();
  c.add_flag("!--ros-best-effort", ros_reliable_,
             "Publish clouds best effort, as LiDAR drivers do (default: reliable)")
      ->default_str("");  // a negated flag: CLI11 would print its bool as {false}
}

int ReplayCommand::run(const ClientOptions& o) {
  auto flags = upsample::upsampleFromFlags(upsample_method_, upsample_input_, upsample_output_,
                                           fov_top_, fov_bottom_, upsample_model_);
  if (!flags) return fail(flags.error().message);
  std::optional<upsample::UpsampleOptions> densify = std::move(*flags);
  if (densify) {
    if (auto ok = densify->validate(); !ok) return fail(ok.error().message);
  }
  auto source = ros2::openAnyScanSource(data_);
  if (!source) return fail(source.error().message);
  auto client = connect(o);
  if (!client) return fail(client.error().message);
  const auto before = (*client)->status();
  std::unique_ptr<RosReplayPublisher> ros_out;
  if (ros_) {
    auto p = rosPublisher(o, ros_namespace_, ros_topic_, ros_frames_, ros_reliable_, rate_,
                          ros_static_delay_s_, before);
    if (!p) return fail(p.error().message);
    ros_out = std::move(*p);
  }
  ReplayRun run(**client, o, query_points_, bbox_edge_m_);
  if (auto ok = run.openCsv(csv_, before); !ok) return fail(ok.error().message);
  const std::size_t end =
      limit_ == 0 ? (*source)->size() : std::min((*source)->size(), first_ + limit_);
  tools::Progress progress("replay: scan", end - first_);
  const auto period = std::chrono::duration_cast<Clock::duration>(
      std::chrono::duration<double>(rate_ > 0 ? 1.0 / rate_ : 0.0));
  const auto start = Clock::now();
  auto slot = start;
  std::optional<std::int64_t> first_stamp;
  std::size_t sent = 0, dropped_points = 0;
  std::optional<RawScan> last_raw;
  // The sender's own cost: it may share the server's cores, as a sensor driver would.
  const ProcessUsage before_all = ProcessUsage::now();
  // Faults are counted over the second half of the scans: the heap and DDS's buffers grow over
  // the first few.
  const std::size_t half_at = (end - first_ + 1) / 2;
  ProcessUsage at_half;
  for (std::size_t i = first_; i < end; ++i, slot += period) {
    auto scan = (*source)->load(i);
    if (!scan) return fail(scan.error().message);
    if (recorded_rate_) {
      if (!scan->stamp_ns) {
        return fail("--recorded-rate needs scans with stamps (a ROS 2 .mcap bag); " + data_ +
                    " has none");
      }
      if (!first_stamp) first_stamp = *scan->stamp_ns;
      slot = start +
             std::chrono::nanoseconds(std::max<std::int64_t>(0, *scan->stamp_ns - *first_stamp));
    }
    // A sensor's missing returns are dropped here, as the ROS path and the offline tools do:
    // the server refuses a whole scan with one NaN (from a broken or hostile publisher).
    dropped_points += scan->removeNonFinitePoints();
    if (densify) {
      if (scan->frame != PointFrame::kSensor) {
        return fail("--upsample needs sensor-frame scans; " + data_ + " stores world-frame points");
      }
      scan->points = upsample::upsamplePoints(scan->points, *densify);
      scan->intensities.clear();
    }
    // The server numbers ROS clouds per topic as they arrive (1, 2, ...): key events on that.
    const RawScan raw = toRawScan(*scan, ros_ ? sent + 1 : i + 1, sensor_id_);
    if (auto ok = run.send(raw, slot, ros_out.get(), sent); !ok) return fail(ok.error().message);
    if (ros_out) last_raw = raw;
    ++sent;
    run.afterScan(scan->originWorld());
    if (sent == half_at) at_half = ProcessUsage::now();
    progress.update(i - first_ + 1, std::to_string(run.integrated()) + " integrated");
  }
  const ProcessUsage after_all = ProcessUsage::now();
  // A cloud stamped after its pose's TF sample needs the next one.
  if (ros_out && last_raw) {
    if (auto ok = ros_out->finish(*last_raw, sent); !ok) return fail(ok.error().message);
  }
  run.drain();
  std::this_thread::sleep_for(std::chrono::milliseconds(1100));  // one more status period
  const auto after = (*client)->status();
  std::printf("replay: sent %zu scans from %s\n", sent, (*source)->describe().c_str());
  if (dropped_points > 0) {
    std::printf("replay: dropped %zu NaN/Inf points before sending\n", dropped_points);
  }
  if (sent > 0) {
    const std::size_t second_half = sent - half_at;
    std::printf(
        "replay: sending took %.2f CPU s in this process (%.1f ms a scan); %ld minor page "
        "faults over the last %zu scans (%.1f a scan)\n",
        after_all.cpu_s - before_all.cpu_s, 1e3 * (after_all.cpu_s - before_all.cpu_s) / sent,
        after_all.minor_faults - at_half.minor_faults, second_half,
        second_half > 0 ? double(after_all.minor_faults - at_half.minor_faults) / second_half
                        : 0.0);
  }
  printServerCounts(before, after);
  run.printLatencies();
  // A replay none of whose scans reached the map failed, whatever the reason.
  if (sent > 0 && before && after && after->integrated == before->integrated) {
    return fail("no scan of " + std::to_string(sent) + " was integrated (rejected " +
                std::to_string(after->rejected - before->rejected) + ", last reason: " +
                (after->last_reject_reason.empty() ? "-" : after->last_reject_reason) + ")");
  }
  return 0;
}

}  // namespace densemap::cli
