#pragma once

// Test access to the client library (never installed): raw requests the public API does not
// send (malformed lengths, one request past the server's limit) and the map inside a snapshot.
#include <span>
#include <vector>

#include "densemap/client/client.hpp"
#include "densemap/map/grid_map.hpp"

namespace densemap::testing {

/// Sends raw coordinates unchecked (split as Client::queryPoints): the server validates them.
[[nodiscard]] Expected<PointQueryAnswer> queryPointsRaw(Client& client,
                                                        const std::vector<float>& xyz);
/// One request of raw coordinates, unsplit (tests of the server's limit).
[[nodiscard]] Expected<PointQueryAnswer> queryPointsOnce(Client& client,
                                                         std::span<const float> xyz);
/// The grid map a snapshot holds (comparisons cell by cell).
[[nodiscard]] const GridMap& gridOf(const MapSnapshot& snapshot);

}  // namespace densemap::testing
