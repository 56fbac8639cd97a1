// DDS Security end to end: densemap-server as a process with a security block, clients with the
// identities of scripts/make-pki.sh (made afresh for the test run), on loopback, one DDS domain
// per test. What it shows: an authenticated robot's scans are integrated; participants without
// credentials, or with another CA's, match nothing and change nothing; a viewer cannot reset or
// clear the map (the middleware refuses its command writer) but can query and fetch the map;
// an operator can; a capture on lo holds a plaintext server's scan payload but not a secure
// server's.
#include <gtest/gtest.h>

#include <signal.h>
#include <spawn.h>
#include <sys/wait.h>
#include <unistd.h>

#include <cstdio>
#include <cstdlib>
#include <fstream>
#include <iterator>
#include <thread>

#include "densemap/client/client.hpp"
#include "densemap/client/testing.hpp"
#include "densemap/test_support/server_clients.hpp"
#include "densemap/test_support/server_process.hpp"
#include "densemap/wire/topics.hpp"
#include "densemap_msgs.h"

namespace densemap {
namespace {

using namespace std::chrono_literals;
namespace fs = std::filesystem;

int run(const std::string& command) { return std::system(command.c_str()); }

/// make-pki.sh's output for the test process (made once; openssl takes ~1 s), and a second
/// PKI with its own CA.
class Pki : public ::testing::Environment {
 public:
  static fs::path dir() { return base() / "pki"; }
  static fs::path otherDir() { return base() / "other"; }
  /// Empty when the PKIs are ready; otherwise why not.
  static const std::string& problem() { return problem_; }
  static bool haveOpenssl() { return run("command -v openssl >/dev/null") == 0; }
  void SetUp() override {
    problem_ = "openssl is not installed";
    if (!haveOpenssl()) return;
    for (const fs::path& d : {dir(), otherDir()}) {
      fs::remove_all(d);
      const std::string command = std::string(DENSEMAP_MAKE_PKI) + " --days 1 " + d.string();
      if (run(command + " >/dev/null") != 0) {
        problem_ = command + " failed";
        return;
      }
    }
    problem_.clear();
  }
  void TearDown() override { fs::remove_all(base()); }

 private:
  static fs::path base() {
    return fs::temp_directory_path() / ("densemap_security_test_" + std::to_string(getpid()));
  }
  static inline std::string problem_ = "not set up";
};

std::string securityBlock(const fs::path& pki) {
  const auto f = [&](const char* name) { return "\"" + (pki / name).string() + "\""; };
  return "security { identity_ca: " + f("ca.pem") + " identity_certificate: " + f("server.pem") +
         " private_key: " + f("server.key") + " permissions_ca: " + f("ca.pem") +
         " governance: " + f("governance.p7s") + " permissions: " + f("permissions.p7s") + " }\n";
}

std::unique_ptr<Client> client(std::uint32_t domain, const std::optional<std::string>& role,
                               const fs::path& pki = Pki::dir(),
                               std::chrono::milliseconds timeout = 10s) {
  ClientOptions o{.domain_id = domain, .timeout = timeout};
  if (role) o.security = dds::SecurityFiles::fromPkiDir(pki.string(), *role);
  auto c = Client::create(o);
  EXPECT_TRUE(c) << c.error().message;
  return c ? std::move(*c) : nullptr;
}

std::vector<RawScan> scans(const fs::path& dir, int n) {
  SequenceOptions o;
  o.scene = "indoor";
  o.sensor = "vlp16";
  o.scans = n;
  o.ground_truth_resolution_m = 0;
  return test::simulatedRawScans(dir, o, "lidar");
}

/// The server's status once it has stopped changing: the same counters for 1.5 s, longer than
/// the 1 s between the server's status samples.
ServerStatus settledStatus(Client& c) {
  auto a = c.status();
  EXPECT_TRUE(a) << a.error().message;
  auto stable_since = std::chrono::steady_clock::now();
  for (const auto deadline = stable_since + 20s;
       a && std::chrono::steady_clock::now() < deadline;) {
    std::this_thread::sleep_for(100ms);
    auto b = c.status();
    EXPECT_TRUE(b);
    if (!b) break;
    const bool same = b->received == a->received && b->map_version == a->map_version &&
                      b->known_cells == a->known_cells && b->integrated == a->integrated;
    if (!same) stable_since = std::chrono::steady_clock::now();
    a = b;
    if (std::chrono::steady_clock::now() - stable_since > 1500ms) break;
  }
  return a ? *a : ServerStatus{};
}

[[maybe_unused]] ::testing::Environment* const kPki = ::testing::AddGlobalTestEnvironment(new Pki);

class Security : public ::testing::Test {
 protected:
  void SetUp() override {
    if (!Pki::haveOpenssl()) GTEST_SKIP() << "openssl is not installed: no DDS Security test";
    ASSERT_EQ(Pki::problem(), "");
    const auto* info = ::testing::UnitTest::GetInstance()->current_test_info();
    dir_ = fs::temp_directory_path() / (std::string("densemap_security_") + info->name());
    fs::remove_all(dir_);
    fs::create_directories(dir_);
  }
  void TearDown() override { fs::remove_all(dir_); }
  fs::path dir_;
};

/// Runs the densemap CLI (another process: Cyclone allows one security identity per process
/// and domain) and returns its exit status and output.
std::pair<int, std::string> cli(const std::string& args) {
  std::string out;
  FILE* pipe = popen((std::string(DENSEMAP_CLI_BIN) + " " + args + " 2>&1").c_str(), "r");
  if (pipe == nullptr) return {-1, "popen failed"};
  char buf[4096];
  while (std::fgets(buf, sizeof buf, pipe) != nullptr) out += buf;
  const int status = pclose(pipe);
  return {WIFEXITED(status) ? WEXITSTATUS(status) : -1, out};
}

std::string as(std::uint32_t domain, const std::string& role, const fs::path& pki = Pki::dir()) {
  return "--domain-id " + std::to_string(domain) + " --pki " + pki.string() + " --role " + role;
}

TEST_F(Security, RobotScansIntegratedStrangersMatchNothingAndChangeNothing) {
  constexpr std::uint32_t kDomain = 191;
  test::ServerProcess server(dir_, kDomain, securityBlock(Pki::dir()), /*capture_log=*/true);
  auto robot = client(kDomain, "robot");
  ASSERT_TRUE(robot);
  auto found = robot->waitForServer();
  ASSERT_TRUE(found) << found.error().message;
  const auto raws = scans(dir_, 4);
  test::replayScans(*robot, raws);                    // a robot may read map/events
  const ServerStatus before = settledStatus(*robot);  // a robot may read status
  EXPECT_EQ(before.integrated, raws.size());
  EXPECT_GT(before.known_cells, 1000u);
  EXPECT_NE(server.log().find("with DDS Security"), std::string::npos) << server.log();
  const auto [viewer_rc, viewer_out] =
      cli(as(kDomain, "viewer") + " query bbox --min -20 -20 -3 --max 20 20 3");
  EXPECT_EQ(viewer_rc, 0) << viewer_out;
  EXPECT_EQ(viewer_out.find("occupied 0,"), std::string::npos) << viewer_out;

  // Without credentials the server is never found, and the scans published change nothing.
  // (Another process: Cyclone cannot add a participant without security to a domain this
  // process holds with security; that is refused clearly.)
  auto plain_here = Client::create({.domain_id = kDomain});
  ASSERT_FALSE(plain_here);
  EXPECT_NE(plain_here.error().message.find("without security"), std::string::npos)
      << plain_here.error().message;
  const std::string replay_data = " --timeout-ms 3000 replay --data " + (dir_ / "data").string();
  const auto [plain_rc, plain_out] = cli("--domain-id " + std::to_string(kDomain) + replay_data);
  EXPECT_NE(plain_rc, 0);
  EXPECT_NE(plain_out.find("no densemap-server found"), std::string::npos) << plain_out;
  // A robot identity signed by another CA: authentication fails, nothing matches.
  const auto [other_rc, other_out] = cli(as(kDomain, "robot", Pki::otherDir()) + replay_data);
  EXPECT_NE(other_rc, 0);
  EXPECT_NE(other_out.find("no densemap-server found"), std::string::npos) << other_out;

  const ServerStatus after = settledStatus(*robot);
  EXPECT_EQ(after.received, before.received);
  EXPECT_EQ(after.map_version, before.map_version);
  EXPECT_EQ(after.known_cells, before.known_cells);
  // One identity per process and domain: a second is refused clearly.
  auto second =
      Client::create({.domain_id = kDomain,
                      .security = dds::SecurityFiles::fromPkiDir(Pki::dir().string(), "viewer")});
  ASSERT_FALSE(second);
  EXPECT_NE(second.error().message.find("one identity per domain"), std::string::npos)
      << second.error().message;
  EXPECT_EQ(server.stop(), 0);
}

TEST_F(Security, ViewerCannotResetOrClearOperatorCan) {
  constexpr std::uint32_t kDomain = 192;
  test::ServerProcess server(dir_, kDomain, securityBlock(Pki::dir()));
  auto viewer = client(kDomain, "viewer");
  ASSERT_TRUE(viewer);
  auto found = viewer->waitForServer();
  ASSERT_TRUE(found) << found.error().message;
  (void)scans(dir_, 3);  // dir_/data
  const auto [replay_rc, replay_out] =
      cli(as(kDomain, "robot") + " replay --data " + (dir_ / "data").string());
  ASSERT_EQ(replay_rc, 0) << replay_out;
  const ServerStatus before = settledStatus(*viewer);
  ASSERT_EQ(before.integrated, 3u);
  ASSERT_GT(before.known_cells, 1000u);

  // The viewer's client has no command writer: DDS Security did not let it create one.
  for (auto refused : {viewer->reset(), viewer->clearBox({-50, -50, -5}, {50, 50, 5})}) {
    ASSERT_FALSE(refused);
    EXPECT_NE(refused.error().message.find("not allowed"), std::string::npos)
        << refused.error().message;
  }
  const auto [cli_reset_rc, cli_reset_out] = cli(as(kDomain, "viewer") + " reset");
  EXPECT_NE(cli_reset_rc, 0);
  EXPECT_NE(cli_reset_out.find("not allowed"), std::string::npos) << cli_reset_out;
  // The same refusal without densemap's client: Cyclone's access control plugin refuses the
  // writer on densemap/cmd/request (and the topic itself) for the viewer's permissions.
  auto raw = dds::createParticipant(
      {kDomain, "lo", dds::SecurityFiles::fromPkiDir(Pki::dir().string(), "viewer")});
  ASSERT_TRUE(raw) << raw.error().message;
  auto topics = dds::Topics::create(*raw);
  ASSERT_TRUE(topics) << topics.error().message;
  auto cmd_writer = dds::createWriter(*raw, topics->command_request, dds::kCommandQos);
  ASSERT_FALSE(cmd_writer);
  EXPECT_TRUE(dds::isNotAllowedBySecurity(cmd_writer.error())) << cmd_writer.error().message;
  EXPECT_FALSE(dds::createWriter(*raw, topics->scan, {.depth = 4}));
  // map/request is granted, for send-map only: a reset sent there is refused by the server.
  auto map_writer = dds::createWriter(*raw, topics->map_request, dds::kCommandQos);
  // Replies come in the asker's own partition (client id 42 here).
  const std::string partition = dds::replyPartition(42);
  dds::QosSpec reply_qos = dds::kCommandQos;
  reply_qos.partition = partition;
  auto reply_reader = dds::createReader(*raw, topics->command_reply, reply_qos);
  ASSERT_TRUE(map_writer && reply_reader);
  for (const auto deadline = std::chrono::steady_clock::now() + 10s;;) {
    dds_publication_matched_status_t m{};
    ASSERT_GE(dds_get_publication_matched_status(map_writer->get(), &m), 0);
    if (m.current_count > 0) break;
    ASSERT_LT(std::chrono::steady_clock::now(), deadline) << "map/request never matched";
    std::this_thread::sleep_for(10ms);
  }
  std::this_thread::sleep_for(200ms);  // the reply writer's side of the match
  densemap_msgs_CommandRequest reset{};
  reset.id = {42, 1};
  reset.kind = 0;
  reset.path = const_cast<char*>("");
  ASSERT_TRUE(dds::write(*map_writer, &reset));
  std::string error;
  for (const auto deadline = std::chrono::steady_clock::now() + 10s;
       error.empty() && std::chrono::steady_clock::now() < deadline;) {
    dds::takeAll<densemap_msgs_CommandReply>(*reply_reader, [&](const auto& r) {
      if (r.id.client_id == 42) error = r.error != nullptr ? r.error : "(none)";
    });
    std::this_thread::sleep_for(10ms);
  }
  EXPECT_NE(error.find("send-map only"), std::string::npos) << error;

  const ServerStatus unchanged = settledStatus(*viewer);
  EXPECT_EQ(unchanged.map_version, before.map_version);
  EXPECT_EQ(unchanged.known_cells, before.known_cells);
  // What a viewer may do: queries and fetching the whole map.
  auto box = viewer->queryBox({-50, -50, -5}, {50, 50, 5});
  ASSERT_TRUE(box) << box.error().message;
  EXPECT_GT(box->occupied + box->free, 1000u);
  auto fetched = viewer->fetchMap(before.map_version);
  ASSERT_TRUE(fetched) << fetched.error().message;
  EXPECT_EQ(fetched->knownCells(), before.known_cells);

  // An operator may reset (but not publish scans).
  const auto [op_replay_rc, op_replay_out] =
      cli(as(kDomain, "operator") + " replay --data " + (dir_ / "data").string());
  EXPECT_NE(op_replay_rc, 0) << op_replay_out;
  const auto [op_rc, op_out] = cli(as(kDomain, "operator") + " reset");
  ASSERT_EQ(op_rc, 0) << op_out;
  const ServerStatus cleared = settledStatus(*viewer);
  EXPECT_EQ(cleared.known_cells, 0u);
  EXPECT_GT(cleared.map_version, before.map_version);
  EXPECT_EQ(cleared.received, before.received);
}

/// tcpdump on lo, writing `file` until stopped.
class Capture {
 public:
  explicit Capture(const fs::path& file) {
    const std::string out = file.string();
    // --immediate-mode: each packet is handed over at once, none is left in the kernel's ring
    // buffer when it stops; -U: each is written at once.
    const char* argv[] = {"tcpdump",   "-i",  "lo",   "--immediate-mode", "-U", "-s", "0", "-w",
                          out.c_str(), "udp", nullptr};
    posix_spawn_file_actions_t actions;
    posix_spawn_file_actions_init(&actions);
    posix_spawn_file_actions_addopen(&actions, 2, "/dev/null", O_WRONLY, 0);
    ok_ = posix_spawnp(&pid_, "tcpdump", &actions, nullptr, const_cast<char**>(argv), environ) == 0;
    posix_spawn_file_actions_destroy(&actions);
    // tcpdump writes the pcap header once it captures; it exits at once without permission.
    for (const auto deadline = std::chrono::steady_clock::now() + 10s;
         ok_ && std::chrono::steady_clock::now() < deadline;) {
      if (waitpid(pid_, nullptr, WNOHANG) == pid_) {
        pid_ = 0;
        ok_ = false;
      } else if (std::error_code ec; fs::file_size(file, ec) >= 24) {
        break;
      }
      std::this_thread::sleep_for(20ms);
    }
    std::this_thread::sleep_for(500ms);
  }
  ~Capture() { stop(); }
  [[nodiscard]] bool ok() const { return ok_; }
  void stop() {
    if (pid_ <= 0) return;
    kill(pid_, SIGINT);
    waitpid(pid_, nullptr, 0);
    pid_ = 0;
  }

 private:
  pid_t pid_ = 0;
  bool ok_ = false;
};

/// A scan whose points repeat 8 distinct points: the CDR payload holds the 12 floats of the
/// first 4 over and over, so every UDP fragment of it contains that byte pattern.
RawScan markerScan(std::uint64_t seq, std::string* marker) {
  RawScan raw;
  raw.sensor_id = "marker";
  raw.seq = seq;
  raw.q_world_sensor = {1, 0, 0, 0};
  for (int i = 0; i < 4000; ++i) {
    const int k = i % 8;
    for (float v : {3.0371f + 0.25f * k, -1.1719f + 0.5f * k, 0.4127f + 0.125f * k}) {
      raw.xyz.push_back(v);
    }
  }
  marker->assign(reinterpret_cast<const char*>(raw.xyz.data()), 12 * sizeof(float));
  return raw;
}

TEST_F(Security, LoopbackCaptureHoldsNoPlaintextScan) {
  if (run("command -v tcpdump >/dev/null") != 0) {
    GTEST_SKIP() << "tcpdump is not installed (scripts/install-deps.sh installs it)";
  }
  for (const bool secure : {false, true}) {
    SCOPED_TRACE(secure ? "with DDS Security" : "plain DDS (the control)");
    const std::uint32_t domain = secure ? 194 : 193;
    const fs::path run_dir = dir_ / (secure ? "secure" : "plain");
    fs::create_directories(run_dir);
    test::ServerProcess server(run_dir, domain, secure ? securityBlock(Pki::dir()) : "");
    auto robot = client(domain, secure ? std::optional<std::string>("robot") : std::nullopt);
    ASSERT_TRUE(robot && robot->waitForServer());
    const fs::path pcap = run_dir / "lo.pcap";
    Capture capture(pcap);
    if (!capture.ok()) GTEST_SKIP() << "tcpdump cannot capture on lo here (needs CAP_NET_RAW)";
    std::string marker;
    ASSERT_NO_FATAL_FAILURE(test::replayScans(*robot, {markerScan(1, &marker)}));
    std::this_thread::sleep_for(1s);
    capture.stop();
    const ServerStatus status = settledStatus(*robot);
    EXPECT_EQ(status.integrated, 1u);
    std::ifstream in(pcap, std::ios::binary);
    const std::string bytes((std::istreambuf_iterator<char>(in)), std::istreambuf_iterator<char>());
    // The scan (48 KB of points) went over lo either way.
    EXPECT_GT(bytes.size(), 48'000u);
    const bool plaintext = bytes.find(marker) != std::string::npos;
    std::printf("%s: %zu bytes captured on lo, scan payload in plaintext: %s\n",
                secure ? "DDS Security" : "plain DDS", bytes.size(), plaintext ? "yes" : "no");
    EXPECT_EQ(plaintext, !secure) << pcap << ": " << bytes.size() << " bytes captured";
  }
}

}  // namespace
}  // namespace densemap
