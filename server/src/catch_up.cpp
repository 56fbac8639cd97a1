#include "catch_up.hpp"

#include <chrono>
#include <cmath>
#include <thread>

#include "densemap/client/client.hpp"
#include "densemap/client/map_snapshot.hpp"
#include "densemap/map/map_factory.hpp"

namespace densemap::server {
namespace {

/// Fetches of the peer's map at most, 0.5 s apart.
constexpr int kCatchUpAttempts = 10;

}  // namespace

Expected<std::string> catchUpFrom(Ingest& ingest, const ServiceOptions& service,
                                  const std::string& peer, double timeout_s) {
  const auto timeout = std::chrono::milliseconds(static_cast<std::int64_t>(timeout_s * 1000));
  auto client = Client::create({.domain_id = service.domain_id,
                                .network_interface = service.network_interface,
                                .timeout = timeout,
                                .security = service.security,
                                .instance = peer});
  if (!client) return makeError("catch-up: " + client.error().message);
  if (auto ok = (*client)->waitForServer(); !ok) {
    return makeError("catch-up from '" + peer + "': " + ok.error().message);
  }
  // A fetch whose map ends before the first scan this server kept is tried again: the peer's
  // next version holds the scans in between.
  Expected<std::string> outcome = makeError("catch-up from '" + peer + "': not tried");
  for (int attempt = 0; attempt < kCatchUpAttempts; ++attempt) {
    std::this_thread::sleep_for(std::chrono::milliseconds(500));
    auto fetched = (*client)->fetchMap();
    if (!fetched) return makeError("catch-up from '" + peer + "': " + fetched.error().message);
    const PipelineOptions& options = ingest.options();
    if (std::abs(fetched->resolution() - options.resolution_m) > 1e-9) {
      return makeError("catch-up from '" + peer + "': its map's resolution " +
                       std::to_string(fetched->resolution()) + " m is not this one's " +
                       std::to_string(options.resolution_m) + " m");
    }
    auto map = makeMap(options.backend, options.resolution_m, SensorModel(options.sensor));
    if (!map) return std::unexpected(map.error());
    // A cell's centre lies half a cell from its faces: it gives back its own key.
    fetched->forEachCell([&](const Point3f& center, float log_odds) {
      if (const auto key = (*map)->grid().pointToKey(center)) (*map)->setLogOdds(*key, log_odds);
    });
    SensorStamps stamps(fetched->lastStamps().begin(), fetched->lastStamps().end());
    outcome = ingest.catchUp(std::move(*map), fetched->version(), std::move(stamps)).get();
    if (outcome || !outcome.error().message.starts_with(Ingest::kCatchUpGap)) break;
  }
  if (!outcome) return makeError("catch-up from '" + peer + "': " + outcome.error().message);
  return outcome;
}

}  // namespace densemap::server
