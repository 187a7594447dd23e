#include "io/output_set.h"

#include <stdlib.h>
#include <sys/stat.h>
#include <unistd.h>

#include <cerrno>
#include <cstring>
#include <system_error>
#include <utility>

#include "io/read_mesh.h"

namespace flank::io {

namespace fs = std::filesystem;

namespace {

// The output path is refused if empty or if something that is not a folder is in the way.
void check_folder_path(const fs::path& folder) {
  if (folder.empty()) throw Error("-o: the output folder is an empty path");
  std::error_code ec;
  const fs::file_status st = fs::status(folder, ec);
  if (fs::exists(st) && !fs::is_directory(st))
    throw Error(folder.string() + ": not a folder (the output -o must be a folder)");
}

void refuse_folders_in_the_way(const fs::path& folder, const std::vector<std::string>& names) {
  for (const std::string& name : names) {
    std::error_code ec;
    if (fs::is_directory(fs::symlink_status(folder / name, ec)))
      throw Error((folder / name).string() + ": is a folder; the output file cannot replace it");
  }
}

}  // namespace

OutputSet::OutputSet(const fs::path& folder, std::vector<std::string> names, std::vector<std::string> stale)
    : folder_(folder), names_(std::move(names)), stale_(std::move(stale)) {
  check_folder_path(folder_);
  std::error_code ec;
  if (!fs::exists(folder_, ec)) {
    fs::create_directories(folder_, ec);
    if (ec) throw Error(folder_.string() + ": cannot create the output folder: " + ec.message());
    created_folder_ = true;
  }
  refuse_folders_in_the_way(folder_, names_);
  refuse_folders_in_the_way(folder_, stale_);
  // A private folder (0700, a name nobody can guess or plant beforehand) for this run's files.
  std::string tmpl = (folder_ / ".flank-run-XXXXXX").string();
  if (::mkdtemp(tmpl.data()) == nullptr) {
    const std::string why = std::strerror(errno);
    if (created_folder_) fs::remove(folder_, ec);
    throw Error(folder_.string() + ": cannot write in the output folder: " + why);
  }
  staging_ = tmpl;
}

OutputSet::~OutputSet() {
  std::error_code ec;
  if (!staging_.empty()) fs::remove_all(staging_, ec);
  if (!committed_ && created_folder_ && fs::is_empty(folder_, ec)) fs::remove(folder_, ec);
}

fs::path OutputSet::staged(const std::string& name) const { return staging_ / name; }

void OutputSet::commit() {
  refuse_folders_in_the_way(folder_, names_);
  refuse_folders_in_the_way(folder_, stale_);
  const fs::path old = staging_ / ".previous";
  std::error_code ec;
  fs::create_directory(old, ec);
  if (ec) throw Error(folder_.string() + ": cannot write in the output folder: " + ec.message());
  // Undo what has been done so far: the new files back to staging, the earlier ones back.
  std::vector<std::string> moved_aside, moved_in;
  auto roll_back = [&] {
    std::error_code e;
    for (const std::string& n : moved_in) fs::rename(folder_ / n, staging_ / n, e);
    for (const std::string& n : moved_aside) fs::rename(old / n, folder_ / n, e);
  };
  for (const std::string& n : names_)
    if (!fs::exists(staging_ / n, ec)) throw Error((folder_ / n).string() + ": was not written");
  // The earlier set aside (removed with the staging folder once the new one is in place).
  std::vector<std::string> earlier = names_;
  earlier.insert(earlier.end(), stale_.begin(), stale_.end());
  for (const std::string& n : earlier) {
    if (fs::exists(fs::symlink_status(folder_ / n, ec))) {
      fs::rename(folder_ / n, old / n, ec);
      if (ec) {
        roll_back();
        throw Error((folder_ / n).string() + ": cannot replace the earlier file: " + ec.message());
      }
      moved_aside.push_back(n);
    }
  }
  for (const std::string& n : names_) {
    fs::rename(staging_ / n, folder_ / n, ec);
    if (ec) {
      roll_back();
      throw Error((folder_ / n).string() + ": cannot move into place: " + ec.message());
    }
    moved_in.push_back(n);
  }
  committed_ = true;
}

void check_output_file(const fs::path& path) {
  if (path.empty()) throw Error("-o: the output file is an empty path");
  std::error_code ec;
  if (fs::is_directory(path, ec)) throw Error(path.string() + ": is a folder, not a file");
  const fs::path dir = path.parent_path().empty() ? fs::path(".") : path.parent_path();
  if (!fs::is_directory(dir, ec)) throw Error(path.string() + ": its folder does not exist");
  // The only sure test that a file can be created there is to create one.
  std::string probe = (dir / ".flank-probe-XXXXXX").string();
  const int fd = ::mkstemp(probe.data());
  if (fd < 0) throw Error(path.string() + ": cannot write in its folder: " + std::strerror(errno));
  ::close(fd);
  ::unlink(probe.c_str());
}

}  // namespace flank::io
