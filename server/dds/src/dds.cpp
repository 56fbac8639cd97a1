#include "densemap/dds/dds.hpp"

#include <cstdlib>
#include <vector>

namespace densemap::dds {

Expected<void> check(dds_return_t rc, std::string_view what) {
  if (rc >= 0) return {};
  return makeError(std::string(what) + " failed: " + dds_strretcode(rc));
}

Expected<dds_entity_t> checkEntity(dds_entity_t e, std::string_view what) {
  if (e > 0) return e;
  return makeError(std::string(what) + " failed: " + dds_strretcode(e));
}

std::string loopbackConfig(const std::string& interface_name) {
  return "<CycloneDDS><Domain Id=\"any\"><General><Interfaces><NetworkInterface name=\"" +
         interface_name +
         "\"/></Interfaces><AllowMulticast>false</AllowMulticast></General>"
         "<Discovery><ParticipantIndex>auto</ParticipantIndex><MaxAutoParticipantIndex>40"
         "</MaxAutoParticipantIndex><Peers><Peer Address=\"127.0.0.1\"/></Peers></Discovery>"
         "<Internal><SocketReceiveBufferSize min=\"4MiB\"/></Internal></Domain></CycloneDDS>";
}

Expected<Entity> createParticipant(std::uint32_t domain_id, const std::string& interface_name) {
  const char* uri = std::getenv("CYCLONEDDS_URI");
  if (uri == nullptr || *uri == '\0') {
    const dds_entity_t domain =
        dds_create_domain(domain_id, loopbackConfig(interface_name).c_str());
    // An existing domain in this process (PRECONDITION_NOT_MET) already has its config.
    if (domain < 0 && domain != DDS_RETCODE_PRECONDITION_NOT_MET) {
      return makeError(std::string("dds_create_domain failed: ") + dds_strretcode(domain));
    }
  }
  auto p =
      checkEntity(dds_create_participant(domain_id, nullptr, nullptr), "dds_create_participant");
  if (!p) return std::unexpected(p.error());
  return Entity(*p);
}

Expected<Entity> createTopic(const Entity& participant, const dds_topic_descriptor_t& descriptor,
                             const std::string& name) {
  auto t =
      checkEntity(dds_create_topic(participant.get(), &descriptor, name.c_str(), nullptr, nullptr),
                  "dds_create_topic " + name);
  if (!t) return std::unexpected(t.error());
  return Entity(*t);
}

namespace {

dds_qos_t* makeQos(const QosSpec& spec) {
  dds_qos_t* qos = dds_create_qos();
  dds_qset_reliability(qos, spec.reliable ? DDS_RELIABILITY_RELIABLE : DDS_RELIABILITY_BEST_EFFORT,
                       DDS_SECS(1));
  if (spec.depth > 0) {
    dds_qset_history(qos, DDS_HISTORY_KEEP_LAST, spec.depth);
  } else {
    dds_qset_history(qos, DDS_HISTORY_KEEP_ALL, DDS_LENGTH_UNLIMITED);
  }
  dds_qset_durability(
      qos, spec.transient_local ? DDS_DURABILITY_TRANSIENT_LOCAL : DDS_DURABILITY_VOLATILE);
  return qos;
}

}  // namespace

Expected<Entity> createReader(const Entity& participant, const Entity& topic, const QosSpec& spec) {
  dds_qos_t* qos = makeQos(spec);
  const dds_entity_t r = dds_create_reader(participant.get(), topic.get(), qos, nullptr);
  dds_delete_qos(qos);
  auto e = checkEntity(r, "dds_create_reader");
  if (!e) return std::unexpected(e.error());
  return Entity(*e);
}

Expected<Entity> createWriter(const Entity& participant, const Entity& topic, const QosSpec& spec) {
  dds_qos_t* qos = makeQos(spec);
  const dds_entity_t w = dds_create_writer(participant.get(), topic.get(), qos, nullptr);
  dds_delete_qos(qos);
  auto e = checkEntity(w, "dds_create_writer");
  if (!e) return std::unexpected(e.error());
  return Entity(*e);
}

Expected<WaitSet> WaitSet::create(const Entity& participant) {
  WaitSet ws;
  auto w = checkEntity(dds_create_waitset(participant.get()), "dds_create_waitset");
  if (!w) return std::unexpected(w.error());
  ws.waitset_ = Entity(*w);
  auto g = checkEntity(dds_create_guardcondition(participant.get()), "dds_create_guardcondition");
  if (!g) return std::unexpected(g.error());
  ws.guard_ = Entity(*g);
  if (auto ok = check(dds_waitset_attach(ws.waitset_.get(), ws.guard_.get(), 0), "attach guard");
      !ok) {
    return std::unexpected(ok.error());
  }
  return ws;
}

Expected<void> WaitSet::attachReader(const Entity& reader, dds_attach_t tag) {
  auto c = checkEntity(dds_create_readcondition(reader.get(), DDS_ANY_STATE),
                       "dds_create_readcondition");
  if (!c) return std::unexpected(c.error());
  conditions_.emplace_back(*c);
  return check(dds_waitset_attach(waitset_.get(), *c, tag), "dds_waitset_attach");
}

std::vector<dds_attach_t> WaitSet::wait(std::chrono::milliseconds timeout) {
  dds_attach_t fired[16];
  const dds_return_t n = dds_waitset_wait(waitset_.get(), fired, 16, DDS_MSECS(timeout.count()));
  std::vector<dds_attach_t> tags;
  for (dds_return_t i = 0; i < n && i < 16; ++i) {
    if (fired[i] == 0) {
      dds_take_guardcondition(guard_.get(), nullptr);
      continue;
    }
    tags.push_back(fired[i]);
  }
  return tags;
}

}  // namespace densemap::dds
