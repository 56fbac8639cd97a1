#pragma once

#include <string>

#include "densemap/geometry/error.hpp"
#include "densemap/server/ingest.hpp"
#include "densemap/server/map_service.hpp"

namespace densemap::server {

/// A replica started late (config dds.catch_up_from, docs/fleet.md): fetches the map of the
/// peer instance `peer` on the service's domain as a client does (send-map: its tiles, version
/// and the last scan seq per sensor in it) and hands it to Ingest::catchUp, which the ingest
/// must have been told to expect (beginCatchUp) before it started. Blocks for the fetch (up
/// to about `timeout_s` per step); returns what the ingest said, or why it could not.
[[nodiscard]] Expected<std::string> catchUpFrom(Ingest& ingest, const ServiceOptions& service,
                                                const std::string& peer, double timeout_s);

}  // namespace densemap::server
