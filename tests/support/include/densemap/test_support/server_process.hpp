#pragma once

#include <gtest/gtest.h>
#include <signal.h>
#include <spawn.h>
#include <sys/wait.h>

#include <fcntl.h>

#include <cstdint>
#include <filesystem>
#include <fstream>
#include <string>

extern char** environ;

namespace densemap::test {

/// A densemap-server process (the binary DENSEMAP_SERVER_BIN, defined by the test's target) on
/// loopback, with its config and snapshot in `dir`: 0.2 m cells, 25 m range, no autosave,
/// DDS domain `domain`, plus `extra` config text. Stopped with SIGTERM when destroyed.
class ServerProcess {
 public:
  /// `capture_log`: the server's stderr goes to `dir/server.log` (appended; see log()).
  /// `autosave_s` > 0: autosave that often, keeping 3 snapshot files.
  /// `map_extra`: more fields of the map block (e.g. "keep_radius_m: 40"); `dds_extra` of the
  /// dds block (e.g. "instance: \"a\"").
  ServerProcess(const std::filesystem::path& dir, std::uint32_t domain,
                const std::string& extra = "", bool capture_log = false, double autosave_s = 0,
                const std::string& map_extra = "", const std::string& dds_extra = "")
      : dir_(dir), capture_log_(capture_log) {
    std::ofstream(dir / "server.textproto")
        << "map { resolution_m: 0.2 max_range_m: 25 " << map_extra << " }\n"
        << "snapshot { path: \"" << (dir / "map.dmap").string()
        << "\" autosave_period_s: " << autosave_s << " keep: 3 }\n"
        << "dds { domain_id: " << domain << " " << dds_extra << " }\n"
        << extra;
    start();
  }
  ~ServerProcess() { stop(); }
  ServerProcess(const ServerProcess&) = delete;
  ServerProcess& operator=(const ServerProcess&) = delete;

  void start() {
    const std::string config = (dir_ / "server.textproto").string();
    const char* argv[] = {DENSEMAP_SERVER_BIN, "--config", config.c_str(), nullptr};
    posix_spawn_file_actions_t actions;
    posix_spawn_file_actions_init(&actions);
    const std::string log = (dir_ / "server.log").string();
    if (capture_log_) {
      posix_spawn_file_actions_addopen(&actions, 2, log.c_str(), O_WRONLY | O_CREAT | O_APPEND,
                                       0644);
    }
    const int rc = posix_spawn(&pid_, DENSEMAP_SERVER_BIN, &actions, nullptr,
                               const_cast<char**>(argv), environ);
    posix_spawn_file_actions_destroy(&actions);
    ASSERT_EQ(rc, 0);
  }
  /// What the server wrote to stderr so far (capture_log only).
  [[nodiscard]] std::string log() const {
    std::ifstream in(dir_ / "server.log");
    return {std::istreambuf_iterator<char>(in), std::istreambuf_iterator<char>()};
  }
  /// SIGKILL: no shutdown snapshot, nothing flushed. Returns after the process is gone.
  void kill9() {
    if (pid_ <= 0) return;
    kill(pid_, SIGKILL);
    int status = 0;
    waitpid(pid_, &status, 0);
    pid_ = 0;
  }
  /// Resident memory of the server process, kB (0 if unknown).
  [[nodiscard]] long residentKb() const {
    std::ifstream in("/proc/" + std::to_string(pid_) + "/status");
    std::string line;
    while (std::getline(in, line)) {
      if (line.rfind("VmRSS:", 0) == 0) return std::stol(line.substr(6));
    }
    return 0;
  }
  [[nodiscard]] pid_t pid() const { return pid_; }
  /// SIGTERM; returns the exit status (-1 if it did not exit normally).
  int stop() {
    if (pid_ <= 0) return -1;
    kill(pid_, SIGTERM);
    int status = 0;
    waitpid(pid_, &status, 0);
    pid_ = 0;
    return WIFEXITED(status) ? WEXITSTATUS(status) : -1;
  }

 private:
  std::filesystem::path dir_;
  bool capture_log_ = false;
  pid_t pid_ = 0;
};

}  // namespace densemap::test
