// The set of files one run writes into its output folder, replaced all or nothing.
//
// A run's files only make sense together (patches.json describes the Ω in envelopes.ply and
// the motion in toolpath.apt), so a run that fails must leave the previous run's set as it
// was, never a mix of two runs. The folder is checked, and created if missing, before any
// work; the files are written into a private staging folder inside it (mkdtemp, mode 0700;
// each file created exclusively, never through a planted symlink) and moved into place
// together at the end. A move that fails puts everything back.
#pragma once

#include <filesystem>
#include <string>
#include <vector>

namespace flank::io {

class OutputSet {
 public:
  // Checks `folder` (a folder or a missing path whose parent can hold one), creates it if
  // missing and makes the staging folder in it. `names` are the files the run will write:
  // one that exists as a folder there is refused now rather than after the work. `stale` are
  // files an earlier run may have left that this run does not write (report.html under
  // --no-report): commit removes them with the rest of the earlier set, so the folder never
  // holds a file of another run. Throws io::Error naming the folder and the problem.
  OutputSet(const std::filesystem::path& folder, std::vector<std::string> names,
            std::vector<std::string> stale = {});
  // Without commit(): removes the staging folder, and the output folder if this set created
  // it and it is empty.
  ~OutputSet();
  OutputSet(const OutputSet&) = delete;
  OutputSet& operator=(const OutputSet&) = delete;

  // Where to write file `name` (one of `names`) before commit.
  std::filesystem::path staged(const std::string& name) const;
  // Moves every staged file into the folder, replacing the earlier run's files of the same
  // names and removing its stale ones; on any failure restores those and throws io::Error.
  void commit();

  const std::filesystem::path& folder() const { return folder_; }

 private:
  std::filesystem::path folder_, staging_;
  std::vector<std::string> names_, stale_;
  bool created_folder_ = false;
  bool committed_ = false;
};

// Refuses, before any work, an output FILE path that cannot be written: empty, a folder, or
// in a folder that does not exist. Throws io::Error naming the path.
void check_output_file(const std::filesystem::path& path);

}  // namespace flank::io
