// Runs the flank command line from tests, as a machinist would: the exit code, stdout and
// stderr of one command, and a fixture with its own scratch folder.
#pragma once

#include <gtest/gtest.h>

#include <sys/wait.h>
#include <unistd.h>

#include <algorithm>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <string>

#include "tests/test_files.h"

namespace flank::cli_test {

namespace fs = std::filesystem;

// A line on the cone envelope the tests synthesize (`flank synth --tool cone:4,7`), for the
// movability and fit commands.
constexpr const char* kLine = "--line 33.75,33.75,-45,33.75,33.75,5";

struct CliRun {
  int code = -1;
  std::string out, err;
};

// The folder of this test process's captured stdout and stderr, removed when the process
// ends: one a process, each command's two files removed once read (ctest runs every test in
// a process of its own, and each had left its folder in the temp folder).
inline const fs::path& capture_dir() {
  struct Scratch {
    fs::path path = fs::temp_directory_path() / ("flank_cli_" + std::to_string(::getpid()));
    Scratch() { fs::create_directories(path); }
    ~Scratch() {
      std::error_code ignored;
      fs::remove_all(path, ignored);
    }
  };
  static const Scratch scratch;
  return scratch.path;
}

inline CliRun run(const std::string& args) {
  static int counter = 0;
  const fs::path& dir = capture_dir();
  const fs::path out = dir / ("out" + std::to_string(counter));
  const fs::path err = dir / ("err" + std::to_string(counter++));
  const std::string cmd = std::string(FLANK_BINARY) + " " + args + " >" + out.string() + " 2>" + err.string();
  CliRun r;
  const int status = std::system(cmd.c_str());
  r.code = WIFEXITED(status) ? WEXITSTATUS(status) : -1;
  r.out = testing::slurp(out);
  r.err = testing::slurp(err);
  std::error_code ignored;
  fs::remove(out, ignored);
  fs::remove(err, ignored);
  return r;
}

class Cli : public ::testing::Test {
 protected:
  void SetUp() override {
    dir_ = fs::temp_directory_path() / ("flank_cli_case_" + std::to_string(::getpid()) + "_" +
                                        ::testing::UnitTest::GetInstance()->current_test_info()->name());
    fs::remove_all(dir_);
    fs::create_directories(dir_);
  }
  void TearDown() override { fs::remove_all(dir_); }
  fs::path file(const std::string& name, const std::string& content) {
    const fs::path p = dir_ / name;
    std::ofstream(p, std::ios::binary) << content;
    return p;
  }
  // One line on stderr naming `what`, exit code non-zero, and the output folder empty.
  void expect_clean_failure(const CliRun& r, const std::string& what, const fs::path& outdir) {
    EXPECT_NE(r.code, 0);
    EXPECT_NE(r.err.find(what), std::string::npos) << r.err;
    EXPECT_EQ(std::count(r.err.begin(), r.err.end(), '\n'), 1) << r.err;
    EXPECT_TRUE(!fs::exists(outdir) || fs::is_empty(outdir)) << outdir;
  }
  fs::path dir_;
};

}  // namespace flank::cli_test
