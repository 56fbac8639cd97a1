#pragma once

// The client's private parts shared by its files: client.cpp (connection, scans, queries,
// commands, status) and client_map.cpp (map versions: events, deltas, fetching the map).
#include <chrono>
#include <optional>
#include <string>

#include "densemap/client/client.hpp"
#include "densemap/wire/dds.hpp"
#include "densemap/wire/topics.hpp"

namespace densemap {
namespace client_detail {

using Clock = std::chrono::steady_clock;

inline void copy3(float (&dst)[3], const Point3f& p) {
  for (int i = 0; i < 3; ++i) dst[i] = p[i];
}

using dds::text;

/// An endpoint DDS Security did not grant is empty: the request fails here, clearly.
inline Expected<void> permitted(const dds::Entity& endpoint, const std::string& what) {
  if (endpoint.get() > 0) return {};
  return makeError(what + ": not allowed by this client's DDS Security permissions");
}

}  // namespace client_detail

struct Client::Dds {
  dds::Entity participant;
  dds::Topics topics;
  // With DDS Security, an endpoint this identity may not use stays empty (0).
  dds::Entity scan_w, pq_w, bq_w, rq_w, cq_w, mq_w;
  dds::Entity pr_r, br_r, rr_r, cr_r, man_r, delta_r, event_r, st_r;
  // One per reply reader: a request waits for data on its own reader, not by polling.
  std::optional<dds::WaitSet> pr_ws, br_ws, rr_ws, cr_ws;
};

}  // namespace densemap
