#include <unistd.h>

#include <fstream>
#include <random>
#include <system_error>

#include "io/read_mesh.h"
#include "io/write.h"

namespace flank::io {

void write_file_atomic(const std::filesystem::path& path,
                       const std::function<void(std::ostream&)>& fill) {
  namespace fs = std::filesystem;
  const fs::path dir = path.parent_path().empty() ? fs::path(".") : path.parent_path();
  std::error_code ec;
  if (!fs::is_directory(dir, ec))
    throw Error(path.string() + ": output folder does not exist");
  // PID and a random suffix keep concurrent writers of the same folder apart.
  std::random_device rd;
  const fs::path tmp = dir / (".tmp-" + path.filename().string() + "-" +
                              std::to_string(::getpid()) + "-" + std::to_string(rd() % 100000));
  try {
    {
      std::ofstream out(tmp, std::ios::binary | std::ios::trunc);
      if (!out) throw Error(path.string() + ": cannot open for writing");
      fill(out);
      out.flush();
      if (!out) throw Error(path.string() + ": write failed (disk full?)");
    }
    fs::rename(tmp, path, ec);
    if (ec) throw Error(path.string() + ": cannot rename into place: " + ec.message());
  } catch (...) {
    fs::remove(tmp, ec);
    throw;
  }
}

}  // namespace flank::io
