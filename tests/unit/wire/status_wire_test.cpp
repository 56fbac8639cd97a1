// The wire library's status conversion (one definition each way): every field of a
// ServerStatus survives writeStatus -> DDS -> statusFromWire. A field either side forgets
// arrives as its default and fails the comparison (each field gets a value of its own).
#include "densemap/wire/status.hpp"

#include <gtest/gtest.h>

#include <chrono>
#include <thread>

#include "densemap/wire/topics.hpp"

namespace densemap {
namespace {

ServerStatus everyFieldSet() {
  ServerStatus s;
  std::uint64_t n = 1;
  for (std::uint64_t* f :
       {&s.received, &s.integrated, &s.dropped, &s.rejected, &s.known_cells, &s.map_version,
        &s.memory_bytes, &s.queries_answered, &s.queries_rejected, &s.rss_bytes, &s.evicted_blocks,
        &s.evicted_cells, &s.snapshot_failures, &s.ros_received, &s.ros_submitted, &s.ros_rejected,
        &s.ros_no_transform, &s.ros_maps_published}) {
    *f = 1000 + n++;
  }
  s.rejected_by_reason = {1, 0, 2, 3, 0, 4, 5};
  s.last_reject_reason = "non-finite point";
  s.latency_p50_ms = 12.5;
  s.latency_p99_ms = 40.25;
  s.uptime_s = 3600.5;
  s.last_query_error = "box too large";
  s.sensors = {{.sensor_id = "front",
                .received = 7,
                .integrated = 5,
                .dropped = 1,
                .rejected = 1,
                .seq_gaps = 2},
               {.sensor_id = "rear",
                .received = 9,
                .integrated = 9,
                .dropped = 0,
                .rejected = 0,
                .seq_gaps = 0}};
  s.last_snapshot_error = "disk full";
  s.cpu_s = 17.75;
  s.ros_enabled = true;
  s.ros_rejected_by_reason = {0, 6, 0, 8};
  s.ros_last_reject = "point step too small";
  s.ros_clouds = {{.topic = "/points", .matched_writers = 2, .incompatible_qos = 3,
                   .last_incompatible_policy = "reliability"},
                  {.topic = "/front/points", .matched_writers = 0, .incompatible_qos = 0,
                   .last_incompatible_policy = ""}};
  return s;
}

TEST(StatusWire, EveryFieldSurvivesTheWire) {
  auto participant = dds::createParticipant({229, "lo", std::nullopt});
  ASSERT_TRUE(participant) << participant.error().message;
  auto topics = dds::Topics::create(*participant);
  ASSERT_TRUE(topics) << topics.error().message;
  auto writer = dds::createWriter(*participant, topics->status, dds::kLatestStateQos);
  auto reader = dds::createReader(*participant, topics->status, dds::kLatestStateQos);
  ASSERT_TRUE(writer && reader);
  const ServerStatus sent = everyFieldSet();
  ASSERT_TRUE(dds::writeStatus(*writer, sent));
  std::optional<ServerStatus> received;
  for (int i = 0; i < 200 && !received; ++i) {
    dds::takeAll<densemap_msgs_Status>(
        *reader, [&](const densemap_msgs_Status& s) { received = dds::statusFromWire(s); });
    if (!received) std::this_thread::sleep_for(std::chrono::milliseconds(10));
  }
  ASSERT_TRUE(received);
  EXPECT_TRUE(*received == sent);
  EXPECT_EQ(received->sensors, sent.sensors);
  EXPECT_EQ(received->ros_last_reject, sent.ros_last_reject);
  EXPECT_EQ(received->latency_p99_ms, sent.latency_p99_ms);
}

}  // namespace
}  // namespace densemap
