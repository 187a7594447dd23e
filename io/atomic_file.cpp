#include <fcntl.h>
#include <sys/stat.h>
#include <unistd.h>

#include <cerrno>
#include <cstring>
#include <sstream>
#include <system_error>

#include "io/read_mesh.h"
#include "io/write_mesh.h"

namespace flank::io {

namespace {

// The process's umask, read without changing it for longer than the call.
mode_t current_umask() {
  const mode_t m = ::umask(022);
  ::umask(m);
  return m;
}

// All of `data` to `fd`, through short writes and EINTR.
bool write_all(int fd, const std::string& data) {
  std::size_t done = 0;
  while (done < data.size()) {
    const ssize_t n = ::write(fd, data.data() + done, data.size() - done);
    if (n < 0 && errno == EINTR) continue;
    if (n <= 0) return false;
    done += static_cast<std::size_t>(n);
  }
  return true;
}

// The folder `path` goes into: it must exist.
std::filesystem::path folder_of(const std::filesystem::path& path) {
  namespace fs = std::filesystem;
  const fs::path dir = path.parent_path().empty() ? fs::path(".") : path.parent_path();
  std::error_code ec;
  if (!fs::is_directory(dir, ec)) throw Error(path.string() + ": output folder does not exist");
  return dir;
}

}  // namespace

void write_file_atomic(const std::filesystem::path& path,
                       const std::function<void(std::ostream&)>& fill) {
  folder_of(path);  // before the work of filling
  // The whole file first, in memory: a writer that throws leaves nothing on disk.
  std::ostringstream buffer;
  fill(buffer);
  if (!buffer) throw Error(path.string() + ": could not format the output");
  write_file_atomic(path, std::move(buffer).str());
}

void write_file_atomic(const std::filesystem::path& path, const std::string& data) {
  namespace fs = std::filesystem;
  const fs::path dir = folder_of(path);
  std::error_code ec;
  // mkstemp creates the temporary exclusively (O_CREAT | O_EXCL): it never opens an existing
  // file or follows a symlink planted under a guessed name.
  std::string tmpl = (dir / (".tmp-" + path.filename().string() + "-XXXXXX")).string();
  const int fd = ::mkstemp(tmpl.data());
  if (fd < 0) throw Error(path.string() + ": cannot create a file in its folder: " + std::strerror(errno));
  const fs::path tmp(tmpl);
  try {
    const bool written = ::fchmod(fd, 0666 & ~current_umask()) == 0 && write_all(fd, data);
    const int write_errno = errno;
    if (::close(fd) != 0 || !written)
      throw Error(path.string() + ": write failed: " + std::strerror(written ? errno : write_errno));
    // rename replaces whatever is at `path`, a symlink included, without following it.
    fs::rename(tmp, path, ec);
    if (ec) throw Error(path.string() + ": cannot move into place: " + ec.message());
  } catch (...) {
    fs::remove(tmp, ec);
    throw;
  }
}

}  // namespace flank::io
