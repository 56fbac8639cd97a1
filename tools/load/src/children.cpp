#include "children.hpp"

#include <spawn.h>
#include <sys/wait.h>

#include <csignal>
#include <fstream>
#include <string>
#include <thread>

#include "densemap/io/process_usage.hpp"

extern char** environ;

namespace densemap::load::detail {

void writeChildResult(const std::filesystem::path& file, const QueryResult& r) {
  std::ofstream out(file);
  out << "late " << r.late_ticks << "\ncpu " << processUsage().cpu_s << '\n';
  for (int k = 0; k < kQueryKinds; ++k) {
    out << "count " << k << ' ' << r.failed[k] << ' ' << r.timeouts[k] << '\n';
    for (const Timed& s : r.latency[k]) out << "q " << k << ' ' << s.t_s << ' ' << s.ms << '\n';
  }
  if (!r.last_error.empty()) out << "error " << r.last_error << '\n';
}

void readChildResult(const std::filesystem::path& file, QueryResult& r) {
  std::ifstream in(file);
  std::string word;
  while (in >> word) {
    if (word == "late") {
      in >> r.late_ticks;
    } else if (word == "cpu") {
      in >> r.cpu_s;
    } else if (word == "count") {
      int k = 0;
      in >> k;
      if (k < 0 || k >= kQueryKinds) return;
      in >> r.failed[k] >> r.timeouts[k];
    } else if (word == "q") {
      int k = 0;
      Timed s;
      in >> k >> s.t_s >> s.ms;
      if (k < 0 || k >= kQueryKinds) return;
      r.latency[k].push_back(s);
      ++r.answered[k];
    } else if (word == "error") {
      std::getline(in, r.last_error);
    } else {
      return;
    }
  }
}

Expected<void> Children::spawn(const RunOptions& o, const Scenario& scenario,
                               Clock::time_point epoch, const std::filesystem::path& tracks,
                               const std::filesystem::path& dir) {
  const auto epoch_ns =
      std::chrono::duration_cast<std::chrono::nanoseconds>(epoch.time_since_epoch()).count();
  for (std::size_t i = 0; i < scenario.clients.size(); ++i) {
    outs_.push_back(dir / ("client-" + std::to_string(i) + ".txt"));
    std::vector<std::string> args = {o.self_exe.string()};
    args.insert(args.end(), o.child_args.begin(), o.child_args.end());
    for (const std::string& a :
         {std::string("--child-client"), std::to_string(i), std::string("--child-epoch-ns"),
          std::to_string(epoch_ns), std::string("--child-out"), outs_.back().string(),
          std::string("--child-tracks"), tracks.string()}) {
      args.push_back(a);
    }
    std::vector<char*> argv;
    for (auto& a : args) argv.push_back(a.data());
    argv.push_back(nullptr);
    pid_t pid = 0;
    if (posix_spawn(&pid, argv[0], nullptr, nullptr, argv.data(), environ) != 0) {
      stop();
      return makeError("cannot start a query-client process (" + o.self_exe.string() + ")");
    }
    pids_.push_back(pid);
  }
  return {};
}

double Children::cpuSeconds() {
  last_cpu_s_.resize(pids_.size(), 0.0);
  double s = 0;
  for (std::size_t i = 0; i < pids_.size(); ++i) {
    last_cpu_s_[i] = std::max(last_cpu_s_[i], processUsage(pids_[i]).cpu_s);
    s += last_cpu_s_[i];
  }
  return s;
}

void Children::collect(std::chrono::seconds grace, std::vector<QueryResult>& results) {
  const auto deadline = Clock::now() + grace;
  for (std::size_t i = 0; i < pids_.size(); ++i) {
    int status = 0;
    while (waitpid(pids_[i], &status, WNOHANG) == 0) {
      if (Clock::now() > deadline) {
        kill(pids_[i], SIGKILL);
        waitpid(pids_[i], &status, 0);
        results[i].last_error = "the client process did not finish in time and was killed";
        break;
      }
      std::this_thread::sleep_for(std::chrono::milliseconds(50));
    }
    // A client whose process failed (exit status, or no result file: it never got to
    // write one) did not run: counted, never reported as "failed 0".
    const bool wrote = std::filesystem::exists(outs_[i]);
    readChildResult(outs_[i], results[i]);
    const bool ok = WIFEXITED(status) && WEXITSTATUS(status) == 0;
    if (!wrote || !ok) {
      results[i].started = false;
      if (results[i].last_error.empty()) {
        results[i].last_error = "the client process failed to start or run (" +
                                std::string(!wrote ? "no result" : "exit status") + ")";
      }
    }
  }
  pids_.clear();
  last_cpu_s_.clear();
}

void Children::stop() {
  for (const pid_t pid : pids_) {
    kill(pid, SIGKILL);
    waitpid(pid, nullptr, 0);
  }
  pids_.clear();
}

}  // namespace densemap::load::detail
