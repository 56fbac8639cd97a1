#include "densemap/ros2/recording.hpp"

#include <algorithm>
#include <limits>
#include <span>

#include "densemap/io/file_bytes.hpp"
#include "densemap/ros2/cdr.hpp"
#include "densemap/ros2/db3.hpp"
#include "densemap/ros2/msg_definitions.hpp"
#include "densemap/ros2/point_cloud2.hpp"
#include "densemap/ros2/replay_frames.hpp"
#include "densemap/ros2/tf_buffer.hpp"

namespace densemap::ros2 {
namespace {

constexpr const char* kCloudType = "sensor_msgs/msg/PointCloud2";
constexpr const char* kTfType = "tf2_msgs/msg/TFMessage";

std::span<const std::uint8_t> bytesOf(const std::string& s) {
  return {reinterpret_cast<const std::uint8_t*>(s.data()), s.size()};
}

/// One cloud of the bag, posed.
struct Cloud {
  BagMessage message;
  Transform T_world_sensor;
  std::int64_t stamp_ns = 0;
};

class RecordingSource final : public ScanSource {
 public:
  RecordingSource(std::unique_ptr<BagReader> reader, std::vector<Cloud> clouds,
                  std::string description, std::size_t max_points)
      : reader_(std::move(reader)),
        clouds_(std::move(clouds)),
        description_(std::move(description)),
        max_points_(max_points) {}
  [[nodiscard]] std::size_t size() const override { return clouds_.size(); }
  [[nodiscard]] std::string describe() const override { return description_; }
  [[nodiscard]] Expected<Scan> load(std::size_t index) const override {
    if (index >= clouds_.size()) return makeError("no scan " + std::to_string(index));
    const Cloud& c = clouds_[index];
    const auto where = [&] {
      return reader_->name() + ": cloud " + std::to_string(index) + " (log time " +
             std::to_string(c.message.log_time) + "): ";
    };
    auto bytes = reader_->data(c.message);
    if (!bytes) return makeError(where() + bytes.error().message);
    auto cloud = decodeCdrPointCloud2(bytesOf(*bytes));
    if (!cloud) return makeError(where() + cloud.error().message);
    auto points = decodePointCloud2(cloud->view(), max_points_);
    if (!points) return makeError(where() + std::string(cloudRejectName(points.error())));
    Scan scan;
    scan.id = index;
    scan.frame = PointFrame::kSensor;
    scan.T_world_sensor = c.T_world_sensor;
    scan.stamp_ns = c.stamp_ns;
    scan.points.reserve(points->xyz.size() / 3);
    for (std::size_t i = 0; i + 2 < points->xyz.size(); i += 3) {
      scan.points.emplace_back(points->xyz[i], points->xyz[i + 1], points->xyz[i + 2]);
    }
    scan.intensities = std::move(points->intensity);
    return scan;
  }

 private:
  std::unique_ptr<BagReader> reader_;
  std::vector<Cloud> clouds_;
  std::string description_;
  std::size_t max_points_;
};

/// The storage of a bag: .mcap, .db3, or a rosbag2 directory's one storage file.
Expected<std::unique_ptr<BagReader>> openBag(const std::filesystem::path& path) {
  std::error_code ec;
  if (std::filesystem::is_directory(path, ec)) {
    // A rosbag2 directory: metadata.yaml beside one storage file (split bags: not read).
    std::vector<std::filesystem::path> files;
    // Advanced with an error code: a directory that changes or turns unreadable while it is
    // listed is an error here, not an exception.
    for (std::filesystem::directory_iterator it(path, ec), end; !ec && it != end;
         it.increment(ec)) {
      if (it->is_regular_file(ec) &&
          (it->path().extension() == ".mcap" || it->path().extension() == ".db3")) {
        files.push_back(it->path());
      }
    }
    if (ec) return fileError(path, "cannot list: " + ec.message());
    if (files.size() != 1) {
      return fileError(path, "a rosbag2 directory needs exactly one .mcap or .db3 file (it has " +
                                 std::to_string(files.size()) + ")");
    }
    return openBag(files.front());
  }
  if (path.extension() == ".db3") {
    auto r = Db3Reader::open(path);
    if (!r) return std::unexpected(r.error());
    return std::unique_ptr<BagReader>(std::move(*r));
  }
  auto r = McapReader::open(path);
  if (!r) return std::unexpected(r.error());
  return std::unique_ptr<BagReader>(std::move(*r));
}

bool isRecording(const std::filesystem::path& path) {
  const auto ext = path.extension();
  if (ext == ".mcap" || ext == ".db3") return true;
  std::error_code ec;
  return std::filesystem::is_directory(path, ec) &&
         std::filesystem::exists(path / "metadata.yaml", ec);
}

}  // namespace

Expected<std::unique_ptr<ScanSource>> openRecording(const std::filesystem::path& path,
                                                    const RecordingOptions& options) {
  auto reader = openBag(path);
  if (!reader) return std::unexpected(reader.error());
  const BagReader& r = **reader;
  // The whole bag's transforms (a bag holds minutes, not the server's 10 s).
  TfBuffer tf(std::numeric_limits<std::int64_t>::max() / 4);
  std::size_t tf_refused = 0, transforms_kept = 0;
  constexpr std::size_t kMaxTransforms = 10'000'000;  // ~640 MB of TF samples
  std::vector<const BagMessage*> clouds;
  std::vector<std::string> cloud_topics;
  for (const BagMessage& m : r.messages()) {
    const BagChannel* c = r.channel(m.channel);
    if (c == nullptr || c->message_encoding != "cdr") continue;
    if (c->schema_name == kTfType && (c->topic == "/tf" || c->topic == "/tf_static")) {
      auto bytes = r.data(m);
      if (!bytes) return fileError(path, bytes.error().message);
      auto transforms = decodeCdrTfMessage(bytesOf(*bytes));
      if (!transforms) {
        return fileError(path, c->topic + " at log time " + std::to_string(m.log_time) + ": " +
                                   transforms.error().message);
      }
      transforms_kept += transforms->size();
      if (transforms_kept > kMaxTransforms) {
        return fileError(path, "more than " + std::to_string(kMaxTransforms) +
                                   " transforms (a bag's TF is kept whole while it is read)");
      }
      for (const CdrTransform& t : *transforms) {
        if (!tf.set(t.header.frame_id, t.child_frame_id, t.sample, c->topic == "/tf_static")) {
          ++tf_refused;
        }
      }
    } else if (c->schema_name == kCloudType &&
               (options.cloud_topic.empty() || options.cloud_topic == c->topic)) {
      clouds.push_back(&m);
      if (std::find(cloud_topics.begin(), cloud_topics.end(), c->topic) == cloud_topics.end()) {
        cloud_topics.push_back(c->topic);
      }
    }
  }
  if (clouds.empty()) {
    return fileError(path, "no " + std::string(kCloudType) + " messages in CDR" +
                               (options.cloud_topic.empty() ? "" : " on " + options.cloud_topic));
  }
  std::stable_sort(clouds.begin(), clouds.end(), [](const BagMessage* a, const BagMessage* b) {
    return a->log_time < b->log_time;
  });
  std::vector<Cloud> posed;
  std::size_t untransformed = 0;
  std::string world;
  // A cloud's header lies in its first bytes: the encapsulation, the stamp and a frame name of
  // at most kCdrMaxString characters (the points are read when the scan is loaded).
  constexpr std::uint64_t kHeaderBytes = 4 + 8 + 4 + kCdrMaxString + 1;
  for (const BagMessage* m : clouds) {
    auto bytes = r.data(*m, kHeaderBytes);
    if (!bytes) return fileError(path, bytes.error().message);
    auto header = decodeCdrCloudHeader(bytesOf(*bytes));
    if (!header) return fileError(path, "a cloud's header: " + header.error().message);
    if (world.empty()) {
      auto direct = tf.lookup(options.world_frame, header->frame_id, header->stamp_ns);
      world = direct || direct.error() == TfFailure::kNotYet || direct.error() == TfFailure::kTooOld
                  ? options.world_frame
                  : tf.rootOf(header->frame_id);
    }
    // Stamp 0 would mean "the latest" to the TF buffer: such a cloud has no time of its own.
    auto T = header->stamp_ns == 0 ? std::unexpected(TfFailure::kNotYet)
                                   : tf.lookup(world, header->frame_id, header->stamp_ns);
    if (!T) {
      ++untransformed;
      continue;
    }
    posed.push_back({*m, *T, header->stamp_ns});
  }
  std::string description =
      r.kind() + " " + r.name() + ": " + std::to_string(posed.size()) + " clouds on";
  for (const std::string& t : cloud_topics) description += " " + t;
  description += " in frame " + world;
  if (untransformed > 0) {
    description += " (" + std::to_string(untransformed) + " without a transform skipped)";
  }
  if (tf_refused > 0) description += " (" + std::to_string(tf_refused) + " transforms refused)";
  if (!r.truncated().empty()) description += " (truncated: " + r.truncated() + ")";
  return std::make_unique<RecordingSource>(std::move(*reader), std::move(posed),
                                           std::move(description), options.max_points);
}

Expected<std::unique_ptr<ScanSource>> openAnyScanSource(const std::filesystem::path& path) {
  if (isRecording(path)) return openRecording(path);
  return openScanSource(path);
}

Expected<void> writeRecording(const ScanSource& source, std::size_t first, std::size_t count,
                              const std::filesystem::path& file, McapCompression compression,
                              const std::function<void(std::size_t)>& progress) {
  const std::string& cloud_definition = pointCloud2Definition();
  const std::string& tf_definition = tfMessageDefinition();
  // Topics 0 /points, 1 /tf, 2 /tf_static; the messages in the order they are recorded.
  const std::vector<Db3Topic> topics{
      {"/points", kCloudType}, {"/tf", kTfType}, {"/tf_static", kTfType}};
  std::vector<Db3Row> rows;
  ReplayFrames frames;
  frames.stamp_base_ns = 1'700'000'000'000'000'000;  // a real time: stamp 0 means "latest"
  const auto stamped = [](const std::string& parent, const std::string& child, TfSample s,
                          std::int64_t stamp) {
    s.stamp_ns = stamp;
    return CdrTransform{{stamp, parent}, child, s};
  };
  const std::int64_t t0 = frames.stampOf(0);
  const CdrTransform statics[] = {stamped(frames.map, frames.odom, TfSample{}, t0),
                                  stamped(frames.base, frames.sensor, sensorMount(), t0)};
  rows.push_back({2, t0, encodeCdrTfMessage(statics)});
  const std::size_t end = std::min(source.size(), first + count);
  for (std::size_t i = first; i < end; ++i) {
    auto scan = source.load(i);
    if (!scan) return std::unexpected(scan.error());
    if (scan->frame != PointFrame::kSensor) {
      return makeError(source.describe() + ": a recording needs sensor-frame scans");
    }
    const std::size_t k = i - first;
    const std::int64_t stamp = frames.stampOf(k);
    const CdrTransform moving[] = {
        stamped(frames.odom, frames.base, odomToBase(scan->T_world_sensor, stamp), stamp)};
    rows.push_back({1, stamp, encodeCdrTfMessage(moving)});
    std::vector<float> xyz;
    xyz.reserve(3 * scan->points.size());
    for (const Point3f& p : scan->points) xyz.insert(xyz.end(), {p.x(), p.y(), p.z()});
    rows.push_back({0, stamp, encodeCdrPointCloud2({stamp, frames.sensor}, xyz)});
    if (progress) progress(k + 1);
  }
  if (file.extension() == ".db3") {
    std::error_code ec;
    std::filesystem::remove(file, ec);  // a new bag replaces an old one, as the MCAP writer's
    return writeDb3(file, topics, rows);
  }
  McapWriter w(compression);
  const std::uint16_t cloud_schema = w.addSchema(kCloudType, "ros2msg", cloud_definition);
  const std::uint16_t tf_schema = w.addSchema(kTfType, "ros2msg", tf_definition);
  std::vector<std::uint16_t> channels;
  for (const Db3Topic& t : topics) {
    channels.push_back(
        w.addChannel(t.type == kCloudType ? cloud_schema : tf_schema, t.name, "cdr"));
  }
  for (const Db3Row& r : rows) {
    w.write(channels[r.topic], static_cast<std::uint64_t>(r.timestamp), r.data);
  }
  auto bytes = w.finish();
  if (!bytes) return fileError(file, bytes.error().message);
  return writeFileAtomically(file, *bytes);
}

}  // namespace densemap::ros2
