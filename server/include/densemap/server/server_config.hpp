#pragma once

#include <optional>

#include <filesystem>

#include "densemap.pb.h"
#include "densemap/geometry/error.hpp"
#include "densemap/server/foxglove_options.hpp"
#include "densemap/server/ingest.hpp"
#include "densemap/server/ros2_bridge.hpp"
#include "densemap/wire/security.hpp"

namespace densemap::server {

/// Reads a protobuf text-format config. Unknown fields, syntax errors and invalid values are
/// errors naming the file, the line and the reason.
[[nodiscard]] Expected<proto::ServerConfig> loadServerConfig(const std::filesystem::path& file);

/// Checks values and converts to the engine's options (the map, the pipeline's limits).
[[nodiscard]] Expected<PipelineOptions> pipelineOptions(const proto::ServerConfig& config);

/// Checks values and converts to the ingest's options: the engine's, the arena and the queue.
[[nodiscard]] Expected<IngestOptions> ingestOptions(const proto::ServerConfig& config);

/// The `security` block's files (each checked readable), or none when there is no block.
[[nodiscard]] Expected<std::optional<dds::SecurityFiles>> securityFiles(
    const proto::ServerConfig& config);

/// The ROS 2 face's options, or none when `ros2.enabled` is false. Errors name the field.
[[nodiscard]] Expected<std::optional<Ros2Options>> ros2Options(const proto::ServerConfig& config);

/// The Foxglove endpoint's options, or none when `foxglove.enabled` is false. Errors name the
/// field.
[[nodiscard]] Expected<std::optional<FoxgloveOptions>> foxgloveOptions(
    const proto::ServerConfig& config);

/// Whether `address` (an IPv4 or IPv6 literal) is a loopback address.
[[nodiscard]] Expected<bool> isLoopbackAddress(const std::string& address);

}  // namespace densemap::server
