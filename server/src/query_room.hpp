#pragma once

#include <cstddef>

#include "densemap/wire/dds.hpp"
#include "densemap/server/ingest.hpp"
#include "replies.hpp"
#include "request_tasks.hpp"

namespace densemap::server {

/// Point, box, ray, distance, path, oriented-box and distance-box queries: takes one request at a
/// time from each reader in turn (no kind starves the others) while the request budget has room, and answers each in a task from the
/// latest published version (one version throughout a multi-cell answer).
class QueryRoom {
 public:
  struct Readers {
    const dds::Entity& point;
    const dds::Entity& bbox;
    const dds::Entity& ray;
    const dds::Entity& distance;
    const dds::Entity& path;
    const dds::Entity& boxes;
    const dds::Entity& distance_box;
  };
  QueryRoom(Ingest& ingest, Readers readers, ReplyWriters& replies, RequestTasks& tasks,
            RequestStats& stats, std::size_t max_query_cells)
      : ingest_(ingest),
        readers_(readers),
        replies_(replies),
        tasks_(tasks),
        stats_(stats),
        max_query_cells_(max_query_cells) {}

  /// Takes the requests waiting (service thread).
  void take();
  /// The memory a point request of `coordinates` floats holds while it is answered.
  [[nodiscard]] static std::size_t pointRequestBytes(std::size_t coordinates);
  /// The same for a distance request (its reply carries 7 floats a point).
  [[nodiscard]] static std::size_t distanceRequestBytes(std::size_t coordinates);
  /// The same for a distance box of `cells` (the reply's float a cell, and its sample).
  [[nodiscard]] static std::size_t distanceBoxBytes(std::size_t cells) {
    return cells * 2 * sizeof(float);
  }

 private:
  Ingest& ingest_;
  Readers readers_;
  ReplyWriters& replies_;
  RequestTasks& tasks_;
  RequestStats& stats_;
  std::size_t max_query_cells_;
};

}  // namespace densemap::server
