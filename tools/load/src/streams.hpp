#pragma once

#include <atomic>
#include <chrono>
#include <filesystem>
#include <map>
#include <memory>
#include <mutex>
#include <optional>
#include <string>
#include <unordered_map>
#include <vector>

#include "densemap/io/raw_scan.hpp"
#include "densemap/io/scan_source.hpp"
#include "densemap/load/runner.hpp"

/// The streams of a load run (runner.cpp in rooms): datasets and tracks, the send
/// times in flight, one sensor's sender and one query client's loop.
namespace densemap::load::detail {

/// A dataset's scans as a sender publishes them (sensor frame, pose as given).
struct Dataset {
  std::vector<RawScan> scans;
};

/// Where a stream's sensor is at each of its scans (world frame, offset applied).
struct Track {
  std::vector<Point3f> origins;
  double rate_hz = 10, start_s = 0;
  bool loop = true;

  [[nodiscard]] Point3f at(double t_s) const {
    if (origins.empty()) return Point3f::Zero();
    const auto i = static_cast<std::size_t>(std::max(0.0, (t_s - start_s) * rate_hz));
    return origins[loop ? i % origins.size() : std::min(i, origins.size() - 1)];
  }
};

/// Send times of scans in flight, shared by the senders and the event reader.
class InFlight {
 public:
  void sent(std::size_t sensor, std::uint64_t seq, double t_s) {
    std::lock_guard lock(mutex_);
    times_[key(sensor, seq)] = t_s;
  }
  /// The send time of a scan whose event arrived, forgotten once returned.
  std::optional<double> seen(std::size_t sensor, std::uint64_t seq) {
    std::lock_guard lock(mutex_);
    const auto it = times_.find(key(sensor, seq));
    if (it == times_.end()) return std::nullopt;
    const double t = it->second;
    times_.erase(it);
    return t;
  }

 private:
  static std::uint64_t key(std::size_t sensor, std::uint64_t seq) {
    return (static_cast<std::uint64_t>(sensor) << 48) | (seq & ((1ULL << 48) - 1));
  }
  std::mutex mutex_;
  std::unordered_map<std::uint64_t, double> times_;
};

[[nodiscard]] double secondsSince(Clock::time_point epoch);

[[nodiscard]] Clock::time_point at(Clock::time_point epoch, double s);

/// Sleeps until `t` or until `stop`, in short steps; false when stopped first.
[[nodiscard]] bool sleepUntil(Clock::time_point t, const std::atomic<bool>& stop);

[[nodiscard]] std::filesystem::path dataPath(const SensorPlan& p,
                                             const std::filesystem::path& work_dir);

/// Streams that replay the same part of the same dataset share one preloaded copy.
[[nodiscard]] std::string datasetKey(const SensorPlan& p, const std::filesystem::path& work_dir);

[[nodiscard]] Expected<std::unique_ptr<ScanSource>> openData(const SensorPlan& p,
                                                             const std::filesystem::path& work_dir);

[[nodiscard]] RawScan withOffset(const RawScan& scan, const Transform& offset);

[[nodiscard]] Expected<std::map<std::string, std::shared_ptr<const Dataset>>> preload(
    const Scenario& scenario, const std::filesystem::path& work_dir);

[[nodiscard]] std::vector<Track> tracksOf(
    const Scenario& scenario, const std::map<std::string, std::shared_ptr<const Dataset>>& data,
    const std::filesystem::path& work_dir);

void writeTracks(const std::filesystem::path& file, const std::vector<Track>& tracks);

[[nodiscard]] Expected<std::vector<Track>> readTracks(const std::filesystem::path& file);

[[nodiscard]] Expected<std::unique_ptr<Client>> connect(const ClientOptions& o);

void runSensor(Client& client, const SensorPlan& plan, std::size_t index, const Dataset& data,
               Clock::time_point epoch, double duration_s, InFlight& in_flight,
               const std::atomic<bool>& stop, SensorResult& out);

/// Point batches, boxes and rays around where the tracked sensor is at the time of asking.
void runQueries(Client& client, const ClientPlan& plan, std::size_t index, const Track& track,
                Clock::time_point epoch, double duration_s, const std::atomic<bool>& stop,
                QueryResult& out);

}  // namespace densemap::load::detail
