#include "io/read_file.h"

#include <fcntl.h>
#include <sys/stat.h>
#include <unistd.h>

#include "kernels/parallel.h"

namespace flank::io {

namespace {
// A piece of a file read on a thread of its own: at least this many bytes. Copying from the
// page cache runs at a few GB/s a core, so a piece is some 0.1 ms; a fork costs tens of µs.
constexpr std::size_t kReadPiece = std::size_t{512} << 10;

std::string why(int error) { return std::string(" (") + std::strerror(error) + ")"; }
}  // namespace

FileBytes read_regular_file(const std::string& path, std::uint64_t max_bytes) {
  const auto fail = [&](const std::string& problem) { throw Error(path + ": " + problem); };
  const auto check = [&](const struct stat& st) {
    if (S_ISDIR(st.st_mode)) fail("cannot open (is a directory)");
    if (!S_ISREG(st.st_mode)) fail("not a regular file");
    if (static_cast<std::uint64_t>(st.st_size) > max_bytes)
      fail("file too large (" + std::to_string(st.st_size) + " bytes; flank reads at most " +
           std::to_string(max_bytes) + ")");
  };
  struct stat st {};
  if (::stat(path.c_str(), &st) != 0) fail("cannot open" + why(errno));
  check(st);
  const int fd = ::open(path.c_str(), O_RDONLY | O_NONBLOCK | O_NOCTTY | O_CLOEXEC);
  if (fd < 0) fail("cannot open" + why(errno));
  struct Closer {
    int fd;
    ~Closer() { ::close(fd); }
  } closer{fd};
  if (::fstat(fd, &st) != 0) fail("cannot open" + why(errno));
  check(st);
  // Reads n bytes at `offset` into `to`, or up to the file's end; returns how many, or -1
  // with errno set (no throw: it runs on worker threads).
  const auto read_at = [fd](char* to, std::size_t n, std::size_t offset) -> std::ptrdiff_t {
    std::size_t done = 0;
    while (done < n) {
      const ssize_t got = ::pread(fd, to + done, n - done, static_cast<off_t>(offset + done));
      if (got < 0 && errno == EINTR) continue;
      if (got < 0) return -1;
      if (got == 0) break;
      done += static_cast<std::size_t>(got);
    }
    return static_cast<std::ptrdiff_t>(done);
  };
  // The size fstat gave, in pieces side by side, into storage one byte longer: reading that
  // byte finds the end, or that the file grew since.
  const auto expected = static_cast<std::size_t>(st.st_size);
  std::size_t capacity = expected + 1;
  auto data = std::make_unique_for_overwrite<char[]>(capacity);
  const std::size_t pieces =
      std::clamp<std::size_t>(expected / kReadPiece, 1, static_cast<std::size_t>(max_threads()));
  const auto bound = [&](std::size_t p) { return expected * p / pieces; };
  std::vector<std::ptrdiff_t> got(pieces, 0);
  std::vector<int> error(pieces, 0);
  parallel_for(0, pieces, [&](std::size_t begin, std::size_t end) {
    for (std::size_t p = begin; p < end; ++p) {
      got[p] = read_at(data.get() + bound(p), bound(p + 1) - bound(p), bound(p));
      error[p] = got[p] < 0 ? errno : 0;
    }
  }, 1);
  std::size_t size = 0;
  bool whole = true;
  for (std::size_t p = 0; p < pieces && whole; ++p) {
    if (got[p] < 0) fail("cannot read" + why(error[p]));
    size += static_cast<std::size_t>(got[p]);
    // A piece that came short: the file shrank while read; what came before it is the file.
    whole = static_cast<std::size_t>(got[p]) == bound(p + 1) - bound(p);
  }
  // Then whatever follows: a file that grows while read (or a /proc file, whose size says 0)
  // keeps to the limit.
  while (whole) {
    if (size == capacity) {
      capacity = static_cast<std::size_t>(
          std::min<std::uint64_t>(std::max<std::size_t>(2 * capacity, 1 << 16), max_bytes + 1));
      auto more = std::make_unique_for_overwrite<char[]>(capacity);
      std::memcpy(more.get(), data.get(), size);
      data = std::move(more);
    }
    const std::ptrdiff_t n = read_at(data.get() + size, capacity - size, size);
    if (n < 0) fail("cannot read" + why(errno));
    size += static_cast<std::size_t>(n);
    if (size > max_bytes)
      fail("file too large (more than " + std::to_string(max_bytes) + " bytes)");
    whole = size == capacity;  // short of it: the end came first
  }
  FileBytes out;
  out.data_ = std::move(data);
  out.size_ = size;
  return out;
}

}  // namespace flank::io
