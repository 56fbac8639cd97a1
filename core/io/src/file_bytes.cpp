#include "densemap/io/file_bytes.hpp"

#include <bzlib.h>
#include <fcntl.h>
#include <unistd.h>

#include <cerrno>
#include <cstring>
#include <fstream>
#include <iterator>

namespace densemap {
namespace {

Expected<std::string> decompressBzip2(const std::filesystem::path& path, const std::string& in) {
  bz_stream stream{};
  if (BZ2_bzDecompressInit(&stream, 0, 0) != BZ_OK) return fileError(path, "bzip2 init failed");
  std::string out;
  char buffer[1 << 16];
  stream.next_in = const_cast<char*>(in.data());
  stream.avail_in = static_cast<unsigned>(in.size());
  int rc = BZ_OK;
  while (rc == BZ_OK) {
    stream.next_out = buffer;
    stream.avail_out = sizeof(buffer);
    rc = BZ2_bzDecompress(&stream);
    out.append(buffer, sizeof(buffer) - stream.avail_out);
    if (rc == BZ_OK && stream.avail_in == 0 && stream.avail_out != 0) break;
  }
  BZ2_bzDecompressEnd(&stream);
  if (rc != BZ_STREAM_END) {
    return fileError(path, "corrupt or truncated bzip2 data (code " + std::to_string(rc) + ")");
  }
  return out;
}

}  // namespace

Expected<std::string> readFileBytes(const std::filesystem::path& path) {
  std::ifstream in(path, std::ios::binary);
  if (!in) return fileError(path, std::string("cannot open: ") + std::strerror(errno));
  std::string bytes((std::istreambuf_iterator<char>(in)), std::istreambuf_iterator<char>());
  if (in.bad()) return fileError(path, "read error");
  if (path.extension() == ".bz2") return decompressBzip2(path, bytes);
  return bytes;
}

Expected<void> writeFileAtomically(const std::filesystem::path& path, const std::string& bytes) {
  const std::filesystem::path tmp = path.string() + ".tmp";
  const int fd = ::open(tmp.c_str(), O_WRONLY | O_CREAT | O_TRUNC, 0644);
  if (fd < 0) return fileError(tmp, std::string("cannot create: ") + std::strerror(errno));
  std::size_t done = 0;
  while (done < bytes.size()) {
    const ssize_t n = ::write(fd, bytes.data() + done, bytes.size() - done);
    if (n < 0) {
      if (errno == EINTR) continue;
      const std::string reason = std::strerror(errno);
      ::close(fd);
      ::unlink(tmp.c_str());
      return fileError(tmp, "write failed: " + reason);
    }
    done += static_cast<std::size_t>(n);
  }
  if (::fsync(fd) != 0 || ::close(fd) != 0) {
    ::unlink(tmp.c_str());
    return fileError(tmp, std::string("fsync/close failed: ") + std::strerror(errno));
  }
  if (::rename(tmp.c_str(), path.c_str()) != 0) {
    ::unlink(tmp.c_str());
    return fileError(path, std::string("rename failed: ") + std::strerror(errno));
  }
  return {};
}

}  // namespace densemap
