#include "densemap/io/text_lines.hpp"

#include <bzlib.h>
#include <fcntl.h>
#include <sys/stat.h>
#include <unistd.h>

#include <cerrno>
#include <cstring>
#include <vector>

#include "densemap/io/file_bytes.hpp"

namespace densemap {

struct TextLines::Impl {
  std::filesystem::path path;
  std::size_t max_line = 0;
  int fd = -1;
  bool bzip2 = false;
  bz_stream bz{};
  bool bz_open = false, bz_end = false, eof = false;
  std::vector<char> raw = std::vector<char>(1 << 16);   // bytes read, not yet decompressed
  std::vector<char> text = std::vector<char>(1 << 16);  // text not yet split into lines
  std::size_t text_begin = 0, text_end = 0;
  std::uint64_t line_no = 0;

  ~Impl() {
    if (bz_open) BZ2_bzDecompressEnd(&bz);
    if (fd >= 0) ::close(fd);
  }

  /// Reads up to `size` bytes of the file into `out`; 0 at its end.
  Expected<std::size_t> readRaw(char* out, std::size_t size) {
    for (;;) {
      const ssize_t n = ::read(fd, out, size);
      if (n >= 0) return static_cast<std::size_t>(n);
      if (errno != EINTR)
        return fileError(path, std::string("read error: ") + std::strerror(errno));
    }
  }

  /// Refills `text` after its unread part; false at the end of the file.
  Expected<bool> refill() {
    if (text_begin > 0) {
      std::memmove(text.data(), text.data() + text_begin, text_end - text_begin);
      text_end -= text_begin;
      text_begin = 0;
    }
    if (text_end == text.size()) text.resize(text.size() * 2);  // a long line (bounded above)
    char* out = text.data() + text_end;
    const std::size_t room = text.size() - text_end;
    if (!bzip2) {
      auto n = readRaw(out, room);
      if (!n) return std::unexpected(n.error());
      text_end += *n;
      return *n > 0;
    }
    while (!bz_end) {
      if (bz.avail_in == 0 && !eof) {
        auto n = readRaw(raw.data(), raw.size());
        if (!n) return std::unexpected(n.error());
        eof = *n == 0;
        bz.next_in = raw.data();
        bz.avail_in = static_cast<unsigned>(*n);
      }
      bz.next_out = out;
      bz.avail_out = static_cast<unsigned>(room);
      const int rc = BZ2_bzDecompress(&bz);
      const std::size_t produced = room - bz.avail_out;
      if (rc == BZ_STREAM_END) bz_end = true;
      if (rc != BZ_OK && rc != BZ_STREAM_END) {
        return fileError(path, "corrupt bzip2 data (code " + std::to_string(rc) + ")");
      }
      if (rc == BZ_OK && eof && bz.avail_in == 0 && produced == 0) {
        return fileError(path, "truncated bzip2 data");
      }
      if (produced > 0) {
        text_end += produced;
        return true;
      }
    }
    return false;
  }
};

TextLines::TextLines(std::unique_ptr<Impl> impl) : impl_(std::move(impl)) {}
TextLines::TextLines(TextLines&&) noexcept = default;
TextLines& TextLines::operator=(TextLines&&) noexcept = default;
TextLines::~TextLines() = default;

Expected<TextLines> TextLines::open(const std::filesystem::path& path, std::size_t max_line_bytes) {
  auto impl = std::make_unique<Impl>();
  impl->path = path;
  impl->max_line = max_line_bytes;
  // POSIX, not iostreams: a directory named where a file is expected is an error, not an
  // exception.
  impl->fd = ::open(path.c_str(), O_RDONLY | O_CLOEXEC | O_NONBLOCK);
  if (impl->fd < 0) return fileError(path, std::string("cannot open: ") + std::strerror(errno));
  struct stat st {};
  if (::fstat(impl->fd, &st) != 0) {
    return fileError(path, std::string("cannot stat: ") + std::strerror(errno));
  }
  if (S_ISDIR(st.st_mode)) return fileError(path, "is a directory, not a file");
  if (!S_ISREG(st.st_mode)) return fileError(path, "is not a regular file");
  impl->bzip2 = path.extension() == ".bz2";
  if (impl->bzip2) {
    if (BZ2_bzDecompressInit(&impl->bz, 0, 0) != BZ_OK) return fileError(path, "bzip2 init failed");
    impl->bz_open = true;
  }
  return TextLines(std::move(impl));
}

Expected<std::optional<std::string>> TextLines::next() {
  Impl& s = *impl_;
  std::size_t scanned = s.text_begin;
  for (;;) {
    const char* begin = s.text.data() + scanned;
    const std::size_t avail = s.text_end - scanned;
    if (std::memchr(begin, '\0', avail) != nullptr) {
      return fileError(s.path,
                       "line " + std::to_string(s.line_no + 1) + ": a NUL byte (not a text file)");
    }
    const auto* newline = static_cast<const char*>(std::memchr(begin, '\n', avail));
    const std::size_t line_end =
        newline != nullptr ? static_cast<std::size_t>(newline - s.text.data()) : s.text_end;
    if (line_end - s.text_begin > s.max_line) {
      return fileError(s.path, "line " + std::to_string(s.line_no + 1) + " is longer than " +
                                   std::to_string(s.max_line) + " bytes");
    }
    if (newline != nullptr) {
      std::string line(s.text.data() + s.text_begin, line_end - s.text_begin);
      s.text_begin = line_end + 1;
      if (!line.empty() && line.back() == '\r') line.pop_back();
      ++s.line_no;
      return std::optional<std::string>(std::move(line));
    }
    const std::size_t consumed = s.text_begin;
    scanned = s.text_end - consumed;  // after refill() moves the unread part to the front
    auto more = s.refill();
    if (!more) return std::unexpected(more.error());
    if (!*more) {
      if (s.text_end == s.text_begin) return std::optional<std::string>();
      std::string line(s.text.data() + s.text_begin, s.text_end - s.text_begin);
      s.text_begin = s.text_end;
      if (!line.empty() && line.back() == '\r') line.pop_back();
      ++s.line_no;
      return std::optional<std::string>(std::move(line));
    }
  }
}

std::uint64_t TextLines::lineNumber() const { return impl_->line_no; }

const std::filesystem::path& TextLines::path() const { return impl_->path; }

}  // namespace densemap
