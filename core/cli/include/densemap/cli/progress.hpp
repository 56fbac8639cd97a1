#pragma once

#include <unistd.h>

#include <cstdio>
#include <string>

namespace densemap::tools {

/// Progress of long work on stderr: one line rewritten in place on a terminal; otherwise (logs,
/// CI) a line at every tenth of the work, so logs stay readable.
class Progress {
 public:
  Progress(std::string label, std::size_t total)
      : label_(std::move(label)), total_(total), tty_(isatty(STDERR_FILENO) == 1) {}

  /// `done` items of `total` finished; `detail` is appended to the line.
  void update(std::size_t done, const std::string& detail = {}) {
    const bool last = done >= total_;
    if (tty_) {
      std::fprintf(stderr, "\r%s %zu/%zu %s\033[K%s", label_.c_str(), done, total_, detail.c_str(),
                   last ? "\n" : "");
      return;
    }
    const std::size_t tenth = total_ == 0 ? 0 : done * 10 / total_;
    if (tenth != last_tenth_ || last) {
      last_tenth_ = tenth;
      std::fprintf(stderr, "%s %zu/%zu %s\n", label_.c_str(), done, total_, detail.c_str());
    }
  }

 private:
  std::string label_;
  std::size_t total_;
  bool tty_;
  std::size_t last_tenth_ = 0;
};

}  // namespace densemap::tools
