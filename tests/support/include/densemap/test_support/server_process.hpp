#pragma once

#include <gtest/gtest.h>
#include <signal.h>
#include <spawn.h>
#include <sys/wait.h>

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
  ServerProcess(const std::filesystem::path& dir, std::uint32_t domain,
                const std::string& extra = "")
      : dir_(dir) {
    std::ofstream(dir / "server.textproto")
        << "map { resolution_m: 0.2 max_range_m: 25 }\n"
        << "snapshot { path: \"" << (dir / "map.dmap").string() << "\" autosave_period_s: 0 }\n"
        << "dds { domain_id: " << domain << " }\n"
        << extra;
    start();
  }
  ~ServerProcess() { stop(); }
  ServerProcess(const ServerProcess&) = delete;
  ServerProcess& operator=(const ServerProcess&) = delete;

  void start() {
    const std::string config = (dir_ / "server.textproto").string();
    const char* argv[] = {DENSEMAP_SERVER_BIN, "--config", config.c_str(), nullptr};
    ASSERT_EQ(posix_spawn(&pid_, DENSEMAP_SERVER_BIN, nullptr, nullptr, const_cast<char**>(argv),
                          environ),
              0);
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
  pid_t pid_ = 0;
};

}  // namespace densemap::test
