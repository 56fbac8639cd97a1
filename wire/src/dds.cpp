#include "densemap/wire/dds.hpp"

#include <thread>

#include <cstdlib>
#include <filesystem>
#include <map>
#include <mutex>
#include <vector>

namespace densemap::dds {

Expected<void> check(dds_return_t rc, std::string_view what) {
  if (rc >= 0) return {};
  return makeError(std::string(what) + " failed: " + dds_strretcode(rc));
}

namespace {

constexpr std::string_view kNotAllowed = "not allowed by this identity's DDS Security permissions";

}  // namespace

Expected<dds_entity_t> checkEntity(dds_entity_t e, std::string_view what) {
  if (e > 0) return e;
  if (e == DDS_RETCODE_NOT_ALLOWED_BY_SECURITY) {
    return makeError(std::string(what) + ": " + std::string(kNotAllowed));
  }
  return makeError(std::string(what) + " failed: " + dds_strretcode(e));
}

bool isNotAllowedBySecurity(const Error& error) {
  return error.message.find(kNotAllowed) != std::string::npos;
}

std::string domainConfig(const std::string& interface_name) {
  // On loopback, discovery is unicast to every participant index's port on 127.0.0.1, each
  // second: a node that announces itself only by multicast (Humble with ROS_LOCALHOST_ONLY=1)
  // never reaches us, and finds us when our announcement reaches its port; at Cyclone's
  // default period that takes 7-8 s. 120 small packets a second on lo.
  const std::string discovery = isLoopbackInterface(interface_name)
                                    ? "<Peers><Peer Address=\"127.0.0.1\"/></Peers>"
                                      "<SPDPInterval>1 s</SPDPInterval>"
                                    : "";
  const std::string multicast =
      isLoopbackInterface(interface_name) ? "<AllowMulticast>false</AllowMulticast>" : "";
  return "<CycloneDDS><Domain Id=\"any\"><General><Interfaces><NetworkInterface name=\"" +
         interface_name + "\"/></Interfaces>" + multicast +
         // 120 processes per domain on one host (parallel CLI queries need more than 40).
         // Unicast discovery port 7400 + 250 d + 10 + 2 i must stay below
         // the next domain's ports (+250): i <= 119.
         "</General><Discovery><ParticipantIndex>auto</ParticipantIndex><MaxAutoParticipantIndex>"
         "119</MaxAutoParticipantIndex>" +
         discovery +
         "</Discovery><Internal><SocketReceiveBufferSize min=\"4MiB\"/></Internal></Domain>"
         "</CycloneDDS>";
}

namespace {

/// Cyclone's built-in plugins (Debian ships them in libddsc0debian/, where its libddsc looks)
/// and the six files, as participant QoS properties.
void setSecurityProperties(dds_qos_t* qos, const SecurityFiles& files) {
  const auto file = [](const std::string& path) {
    return "file:" + std::filesystem::absolute(path).string();
  };
  const char* plugins[][4] = {
      {"auth", "dds_security_auth", "init_authentication", "finalize_authentication"},
      {"crypto", "dds_security_crypto", "init_crypto", "finalize_crypto"},
      {"access", "dds_security_ac", "init_access_control", "finalize_access_control"},
  };
  for (const auto& p : plugins) {
    const std::string prefix = std::string("dds.sec.") + p[0] + ".library.";
    dds_qset_prop(qos, (prefix + "path").c_str(), p[1]);
    dds_qset_prop(qos, (prefix + "init").c_str(), p[2]);
    dds_qset_prop(qos, (prefix + "finalize").c_str(), p[3]);
  }
  for (const SecurityFileField& f : kSecurityFileFields) {
    dds_qset_prop(qos, f.property, file(files.*f.member).c_str());
  }
}

/// With security, Cyclone's receive threads decrypt with OpenSSL until Cyclone is torn down,
/// which by default happens in its library destructor: after OpenSSL's atexit cleanup, so a
/// packet arriving during exit crashed the process (seen: 1 exit in 2 of `densemap status`).
/// Registered after the first secure participant (and so after OpenSSL's own atexit), this
/// stops Cyclone first.
void stopCycloneBeforeOpenSslAtExit() {
  static std::once_flag once;
  std::call_once(once, [] { std::atexit([] { dds_delete(DDS_CYCLONEDDS_HANDLE); }); });
}

/// Cyclone 0.10's access control plugin keeps one set of local permissions per domain in a
/// process (ACCESS_CONTROL_USE_ONE_PERMISSION): a second identity there would be checked
/// locally against the first's grants (and refused by its peers against its own), and a
/// participant without security fails to validate. Both are refused here instead, clearly
/// (for the process's life: the domain and its plugins stay loaded).
std::mutex identities_mutex;
std::map<std::uint32_t, std::string> identities;  // domain -> identity certificate

std::string identityOf(const SecurityFiles& files) {
  return std::filesystem::absolute(files.identity_certificate).string();
}

/// Whether a participant with `files` (none: plain) may join `domain_id` in this process.
Expected<void> checkIdentity(std::uint32_t domain_id, const std::optional<SecurityFiles>& files) {
  const std::lock_guard lock(identities_mutex);
  const auto it = identities.find(domain_id);
  if (it == identities.end()) return {};
  if (!files) {
    return makeError("DDS domain " + std::to_string(domain_id) + " has DDS Security identity " +
                     it->second +
                     " in this process; Cyclone DDS cannot add a participant without security "
                     "to it (use another process)");
  }
  if (it->second == identityOf(*files)) return {};
  return makeError("DDS domain " + std::to_string(domain_id) +
                   " already has DDS Security identity " + it->second +
                   " in this process; Cyclone DDS allows one identity per domain " +
                   "and process (use another process for " + identityOf(*files) + ")");
}

void recordIdentity(std::uint32_t domain_id, const SecurityFiles& files) {
  const std::lock_guard lock(identities_mutex);
  identities.emplace(domain_id, identityOf(files));
}

}  // namespace

Expected<Entity> createParticipant(const ParticipantOptions& options) {
  const char* uri = std::getenv("CYCLONEDDS_URI");
  if (uri == nullptr || *uri == '\0') {
    const dds_entity_t domain =
        dds_create_domain(options.domain_id, domainConfig(options.network_interface).c_str());
    // An existing domain in this process (PRECONDITION_NOT_MET) already has its config.
    if (domain < 0 && domain != DDS_RETCODE_PRECONDITION_NOT_MET) {
      return makeError(std::string("dds_create_domain failed: ") + dds_strretcode(domain));
    }
  }
  if (options.security) {
    if (auto ok = checkSecurityFiles(*options.security); !ok) return std::unexpected(ok.error());
  }
  if (auto ok = checkIdentity(options.domain_id, options.security); !ok) {
    return std::unexpected(ok.error());
  }
  dds_qos_t* qos = nullptr;
  if (options.security) {
    qos = dds_create_qos();
    setSecurityProperties(qos, *options.security);
  }
  const dds_entity_t p = dds_create_participant(options.domain_id, qos, nullptr);
  if (qos != nullptr) dds_delete_qos(qos);
  if (p < 0 && options.security) {
    return makeError(std::string("dds_create_participant with DDS Security failed (") +
                     dds_strretcode(p) +
                     "): the identity certificate must be signed by identity_ca and match its "
                     "private key, governance and permissions must be signed by permissions_ca, "
                     "and the permissions must hold a valid grant for this certificate's subject "
                     "on this domain");
  }
  auto e = checkEntity(p, "dds_create_participant");
  if (!e) return std::unexpected(e.error());
  if (options.security) {
    recordIdentity(options.domain_id, *options.security);
    stopCycloneBeforeOpenSslAtExit();
  }
  return Entity(*e);
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
  if (!spec.partition.empty()) dds_qset_partition1(qos, std::string(spec.partition).c_str());
  if (spec.xcdr1_only) {
    dds_data_representation_id_t xcdr1[1] = {DDS_DATA_REPRESENTATION_XCDR1};
    dds_qset_data_representation(qos, 1, xcdr1);
  }
  return qos;
}

}  // namespace

Expected<Entity> createReader(const Entity& participant, const Entity& topic, const QosSpec& spec) {
  if (topic.get() <= 0) {
    auto e = checkEntity(DDS_RETCODE_NOT_ALLOWED_BY_SECURITY, "dds_create_reader");
    return std::unexpected(e.error());
  }
  dds_qos_t* qos = makeQos(spec);
  const dds_entity_t r = dds_create_reader(participant.get(), topic.get(), qos, nullptr);
  dds_delete_qos(qos);
  auto e = checkEntity(r, "dds_create_reader");
  if (!e) return std::unexpected(e.error());
  return Entity(*e);
}

Expected<Entity> createWriter(const Entity& participant, const Entity& topic, const QosSpec& spec) {
  if (topic.get() <= 0) {
    auto e = checkEntity(DDS_RETCODE_NOT_ALLOWED_BY_SECURITY, "dds_create_writer");
    return std::unexpected(e.error());
  }
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

std::optional<dds_guid_t> participantOfWriter(const Entity& reader,
                                              dds_instance_handle_t publication) {
  dds_builtintopic_endpoint_t* e = dds_get_matched_publication_data(reader.get(), publication);
  if (e == nullptr) return std::nullopt;
  const dds_guid_t participant = e->participant_key;
  dds_builtintopic_free_endpoint(e);
  return participant;
}

bool waitForReaderOf(const Entity& writer, const dds_guid_t& participant,
                     std::chrono::milliseconds timeout) {
  const auto deadline = std::chrono::steady_clock::now() + timeout;
  std::vector<dds_instance_handle_t> handles(64);
  while (true) {
    const dds_return_t n =
        dds_get_matched_subscriptions(writer.get(), handles.data(), handles.size());
    if (n > static_cast<dds_return_t>(handles.size())) {  // more than room: grow and ask again
      handles.resize(static_cast<std::size_t>(n) * 2);
      continue;
    }
    for (dds_return_t i = 0; i < n; ++i) {
      dds_builtintopic_endpoint_t* e = dds_get_matched_subscription_data(writer.get(), handles[i]);
      if (e == nullptr) continue;
      const bool same = std::equal(std::begin(e->participant_key.v), std::end(e->participant_key.v),
                                   std::begin(participant.v));
      dds_builtintopic_free_endpoint(e);
      if (same) return true;
    }
    if (std::chrono::steady_clock::now() >= deadline) return false;
    std::this_thread::sleep_for(std::chrono::milliseconds(2));
  }
}

}  // namespace densemap::dds
