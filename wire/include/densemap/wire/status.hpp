#pragma once

#include "densemap/wire/dds.hpp"
#include "densemap/wire/server_status.hpp"

// The IDL type (densemap_msgs.h, generated; not installed with the SDK).
struct densemap_msgs_Status;

namespace densemap {

namespace dds {

/// Writes `status` on `writer` (densemap/status).
[[nodiscard]] Expected<void> writeStatus(const Entity& writer, const ServerStatus& status);
/// A received sample as a ServerStatus (every field; absent strings as empty).
[[nodiscard]] ServerStatus statusFromWire(const densemap_msgs_Status& sample);

}  // namespace dds
}  // namespace densemap
