// A rosbag2 SQLite bag (.db3) as a user's recording arrives: the database (SQLite's own
// checks), our reading of its topics and messages, then each message's CDR cloud or transforms.
#include <unistd.h>

#include <cstdio>
#include <string>

#include "densemap/ros2/db3.hpp"
#include "fuzz_bag.hpp"

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  // SQLite reads files: the input goes to this process's own file.
  static const std::string path = "/tmp/fuzz_db3_" + std::to_string(getpid()) + ".db3";
  static const struct Remove {  // gone when the fuzzer exits
    ~Remove() { std::remove(path.c_str()); }
  } remove_at_exit;
  if (std::FILE* f = std::fopen(path.c_str(), "wb")) {
    std::fwrite(data, 1, size, f);
    std::fclose(f);
  } else {
    return 0;
  }
  auto reader = densemap::ros2::Db3Reader::open(path, 4096);
  if (!reader) return 0;
  densemap::fuzz::decodeEveryMessage(**reader);
  return 0;
}
