#include "densemap/io/file_bytes.hpp"

#include <bzlib.h>
#include <fcntl.h>
#include <sys/stat.h>
#include <unistd.h>

#include <cerrno>
#include <cstring>

namespace densemap {
namespace {

std::string sizeText(std::uint64_t bytes) { return std::to_string(bytes) + " bytes"; }

Expected<std::string> decompressBzip2(const std::filesystem::path& path, const std::string& in,
                                      std::uint64_t max_bytes) {
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
    const std::size_t produced = sizeof(buffer) - stream.avail_out;
    // The cap applies to what the file expands to, before it is held (a bzip2 bomb).
    if (out.size() + produced > max_bytes) {
      BZ2_bzDecompressEnd(&stream);
      return fileError(path, "decompresses to more than the limit of " + sizeText(max_bytes));
    }
    out.append(buffer, produced);
    if (rc == BZ_OK && stream.avail_in == 0 && stream.avail_out != 0) break;
  }
  BZ2_bzDecompressEnd(&stream);
  if (rc != BZ_STREAM_END) {
    return fileError(path, "corrupt or truncated bzip2 data (code " + std::to_string(rc) + ")");
  }
  return out;
}

/// Closes a descriptor on every path out.
struct FdCloser {
  int fd;
  ~FdCloser() {
    if (fd >= 0) ::close(fd);
  }
};

}  // namespace

Expected<std::string> readFileBytes(const std::filesystem::path& path, std::uint64_t max_bytes) {
  // POSIX reads, not iostreams: a directory or a device named where a file is expected must be
  // an error, not an exception (libstdc++'s filebuf throws on EISDIR).
  const int fd = ::open(path.c_str(), O_RDONLY | O_CLOEXEC | O_NONBLOCK);
  if (fd < 0) return fileError(path, std::string("cannot open: ") + std::strerror(errno));
  const FdCloser closer{fd};
  struct stat st {};
  if (::fstat(fd, &st) != 0)
    return fileError(path, std::string("cannot stat: ") + std::strerror(errno));
  if (S_ISDIR(st.st_mode)) return fileError(path, "is a directory, not a file");
  if (!S_ISREG(st.st_mode)) return fileError(path, "is not a regular file");
  const auto size = static_cast<std::uint64_t>(st.st_size);
  if (size > max_bytes) {
    return fileError(path, "is " + sizeText(size) + ", over the limit of " + sizeText(max_bytes));
  }
  std::string bytes(size, '\0');
  std::size_t done = 0;
  while (done < bytes.size()) {
    const ssize_t n = ::read(fd, bytes.data() + done, bytes.size() - done);
    if (n < 0) {
      if (errno == EINTR) continue;
      return fileError(path, std::string("read error: ") + std::strerror(errno));
    }
    if (n == 0) break;  // the file shrank while read: keep what is there
    done += static_cast<std::size_t>(n);
  }
  bytes.resize(done);
  if (path.extension() == ".bz2") return decompressBzip2(path, bytes, max_bytes);
  return bytes;
}

Expected<void> writeFileAtomically(const std::filesystem::path& path, const std::string& bytes,
                                   unsigned mode) {
  // A temporary name of its own (mkstemp: O_EXCL, never an existing file or link), so two
  // writers of the same path never share or truncate each other's temporary file.
  std::string tmp_name = path.string() + ".tmp.XXXXXX";
  const int fd = ::mkostemp(tmp_name.data(), O_CLOEXEC);
  const std::filesystem::path tmp = tmp_name;
  if (fd < 0) {
    return fileError(path.string() + ".tmp", std::string("cannot create: ") + std::strerror(errno));
  }
  if (::fchmod(fd, static_cast<mode_t>(mode)) != 0) {
    const std::string reason = std::strerror(errno);
    ::close(fd);
    ::unlink(tmp.c_str());
    return fileError(tmp, "chmod failed: " + reason);
  }
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
    const std::string reason = std::strerror(errno);
    ::unlink(tmp.c_str());
    return fileError(path, "rename failed: " + reason);
  }
  return {};
}

}  // namespace densemap
