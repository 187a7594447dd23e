// The command line as an attacker and a clumsy user meet it (issue "Reliability"): output
// sets replaced all or nothing, no write through a planted symlink, no gouging result called
// a success, and every impossible option refused up front in one line naming it.
#include <gtest/gtest.h>

#include <sys/stat.h>

#include <map>
#include <string>

#include "io/output_set.h"
#include "io/read_mesh.h"
#include "io/write_mesh.h"
#include "tests/cli_run.h"
#include "tests/test_files.h"

namespace {

using namespace flank::cli_test;

using flank::testing::slurp;

class Reliability : public Cli {
 protected:
  void SetUp() override {
    Cli::SetUp();
    mesh_ = dir_ / "part.stl";
    ASSERT_EQ(run("synth --guides seed003 --tool cylinder:5 --resolution 61x21 -o " + mesh_.string()).code, 0);
  }
  // A fast fit into `out`.
  CliRun fit(const fs::path& out, const std::string& extra = "") {
    return run("fit " + mesh_.string() + " " + kLine + " --tool cylinder --tolerance-rel 5e-4 -q " + extra +
               " -o " + out.string());
  }
  fs::path mesh_;
};

const char* kOutputs[] = {"patches.json", "envelopes.ply", "design.ply", "toolpath.apt"};

// Row 1: a run that fails leaves the earlier run's set as it was, not a mix of two runs.
TEST_F(Reliability, FailedRunLeavesTheEarlierSetIntact) {
  const fs::path out = dir_ / "o";
  ASSERT_EQ(fit(out).code, 0);
  std::map<std::string, std::string> before;
  for (const char* n : kOutputs) before[n] = slurp(out / n);
  // One output name taken by a folder: the new run cannot place its set.
  fs::remove(out / "design.ply");
  fs::create_directories(out / "design.ply");
  before.erase("design.ply");
  const CliRun r = fit(out, "--apt-steps 50");
  EXPECT_EQ(r.code, 2);
  EXPECT_NE(r.err.find("design.ply"), std::string::npos) << r.err;
  EXPECT_EQ(std::count(r.err.begin(), r.err.end(), '\n'), 1) << r.err;
  for (const auto& [name, content] : before) EXPECT_EQ(slurp(out / name), content) << name;
  for (const auto& e : fs::directory_iterator(out))  // no staging folder or temporary left
    EXPECT_NE(e.path().filename().string()[0], '.') << e.path();
}

// Row 1, at the last step: a failure while moving the set into place puts the earlier set back.
TEST(OutputSet, CommitIsAllOrNothing) {
  const fs::path dir = fs::temp_directory_path() / ("flank_outset_" + std::to_string(::getpid()));
  fs::remove_all(dir);
  fs::create_directories(dir);
  for (const char* n : {"a.txt", "b.txt"}) std::ofstream(dir / n) << "old " << n;
  {
    flank::io::OutputSet set(dir, {"a.txt", "b.txt"});
    flank::io::write_file_atomic(set.staged("a.txt"), [](std::ostream& o) { o << "new a"; });
    flank::io::write_file_atomic(set.staged("b.txt"), [](std::ostream& o) { o << "new b"; });
    // Something takes b.txt's place as a folder between the work and the commit.
    fs::remove(dir / "b.txt");
    fs::create_directories(dir / "b.txt" / "x");
    EXPECT_THROW(set.commit(), flank::io::Error);
  }
  EXPECT_EQ(slurp(dir / "a.txt"), "old a.txt");
  EXPECT_TRUE(fs::is_directory(dir / "b.txt"));
  int entries = 0;
  for (const auto& e : fs::directory_iterator(dir)) entries += e.path().filename().string()[0] == '.';
  EXPECT_EQ(entries, 0);  // the staging folder is gone
  {
    flank::io::OutputSet set(dir, {"a.txt"});
    flank::io::write_file_atomic(set.staged("a.txt"), [](std::ostream& o) { o << "new a"; });
    set.commit();
  }
  EXPECT_EQ(slurp(dir / "a.txt"), "new a");
  fs::remove_all(dir);
}

// A file of the earlier set that this run does not write (report.html under --no-report)
// goes at commit, and comes back if the commit fails.
TEST(OutputSet, StaleFilesGoWithTheEarlierSet) {
  const fs::path dir = fs::temp_directory_path() / ("flank_outset_stale_" + std::to_string(::getpid()));
  fs::remove_all(dir);
  fs::create_directories(dir);
  for (const char* n : {"a.txt", "report.html"}) std::ofstream(dir / n) << "old " << n;
  {
    flank::io::OutputSet set(dir, {"a.txt", "b.txt"}, {"report.html"});
    flank::io::write_file_atomic(set.staged("a.txt"), [](std::ostream& o) { o << "new a"; });
    flank::io::write_file_atomic(set.staged("b.txt"), [](std::ostream& o) { o << "new b"; });
    fs::create_directories(dir / "b.txt" / "x");  // the commit fails
    EXPECT_THROW(set.commit(), flank::io::Error);
  }
  EXPECT_EQ(slurp(dir / "report.html"), "old report.html");
  EXPECT_EQ(slurp(dir / "a.txt"), "old a.txt");
  fs::remove_all(dir / "b.txt");
  {
    flank::io::OutputSet set(dir, {"a.txt"}, {"report.html"});
    flank::io::write_file_atomic(set.staged("a.txt"), [](std::ostream& o) { o << "new a"; });
    set.commit();
  }
  EXPECT_EQ(slurp(dir / "a.txt"), "new a");
  EXPECT_FALSE(fs::exists(dir / "report.html"));
  // A folder in a stale file's place is refused before any work.
  fs::create_directories(dir / "report.html");
  EXPECT_THROW(flank::io::OutputSet(dir, {"a.txt"}, {"report.html"}), flank::io::Error);
  fs::remove_all(dir);
}

// Row 2: symlinks planted at the output names are replaced, never written through.
TEST_F(Reliability, PlantedSymlinksAreNotFollowed) {
  const fs::path out = dir_ / "o";
  fs::create_directories(out);
  const fs::path victim = dir_ / "victim.txt";
  std::ofstream(victim) << "precious";
  for (const char* n : kOutputs) fs::create_symlink(victim, out / n);
  ASSERT_EQ(fit(out).code, 0);
  EXPECT_EQ(slurp(victim), "precious");
  for (const char* n : kOutputs) EXPECT_TRUE(fs::is_regular_file(fs::symlink_status(out / n))) << n;
  // The same for a single output file (synth).
  const fs::path link = dir_ / "linked.stl";
  fs::create_symlink(victim, link);
  ASSERT_EQ(run("synth --guides seed003 --tool cylinder:5 --resolution 21x11 -o " + link.string()).code, 0);
  EXPECT_EQ(slurp(victim), "precious");
  EXPECT_TRUE(fs::is_regular_file(fs::symlink_status(link)));
}

// Row 3: a result that gouges beyond the tolerance is never a success, however sparsely the
// fit was sampled: either refused (exit 1, nothing written) or gouge-free.
TEST_F(Reliability, SparseSamplingNeverPassesAGouge) {
  const fs::path out = dir_ / "o";
  const CliRun r = run("fit " + mesh_.string() + " " + kLine + " --samples-t 8 --samples-s 4 -q -o " + out.string());
  if (r.code == 0) {
    const std::string json = slurp(out / "patches.json");
    const auto tol_at = json.find("\"tolerance\":");
    const auto gouge_at = json.find("\"max_gouge\":");
    ASSERT_NE(tol_at, std::string::npos);
    ASSERT_NE(gouge_at, std::string::npos);
    EXPECT_LE(std::stod(json.substr(gouge_at + 12)), std::stod(json.substr(tol_at + 12))) << r.out;
  } else {
    EXPECT_EQ(r.code, 1) << r.err;
    EXPECT_NE(r.err.find("gouge"), std::string::npos) << r.err;
    EXPECT_FALSE(fs::exists(out));
  }
}

// Rows 4, 7, 11, 12, 13: impossible options get one line naming the option, exit 2, no output.
TEST_F(Reliability, ImpossibleOptionsAreNamed) {
  const fs::path out = dir_ / "o";
  const std::string m = mesh_.string() + " -q -o " + out.string() + " ";
  const std::pair<std::string, std::string> cases[] = {
      {"fit " + m + "--line 1,1,1,1,1,1.000000000001", "--line"},
      {"fit " + m + kLine + " --samples-t 100000 --samples-s 10000", "--samples-t"},
      {"fit " + m + kLine + " --samples-s 10000", "--samples-s"},
      {"decompose " + m + "--length 1e-300,1e-300", "--length"},
      {"decompose " + m + "--length 0.5,0.5", "--length"},
      {"decompose " + m + "--length 10,1e300", "--length"},
      {"decompose " + m + "--radius 1e-300,1", "--radius"},
      {"decompose " + m + "--tolerance ''", "--tolerance"},
      {"decompose " + m + "--holder ''", "--holder"},
      {"decompose " + m + "--tool 'cone,'", "--tool"},
      {"decompose " + m + "--tool ''", "--tool"},
      {"decompose " + m + "--radius 0x10,20", "--radius"},
      {"decompose " + m + "--radius 1,,20", "--radius"},
      {"decompose " + m + "--radius inf,20", "--radius"},
      {"decompose " + m + "--coverage nan", "--coverage"},
      {"fit " + m + kLine + " --holder 30,", "--holder"},
  };
  for (const auto& [args, option] : cases) {
    SCOPED_TRACE(args);
    expect_clean_failure(run(args), option, out);
    EXPECT_FALSE(fs::exists(out));
  }
  const fs::path part = dir_ / "x.stl";
  const std::pair<std::string, std::string> synth[] = {
      {"--guides seed003 --tool cylinder:5 --resolution 30000x30000", "--resolution"},
      {"--guides seed003 --tool cylinder:5 --length 1e300", "--length"},
      {"--motion " + file("same.txt", "0 0 0 0 0 1\n0 0 0 0 0 1\n0 0 0 0 0 1\n0 0 0 0 0 1\n").string() +
           " --tool cylinder:5",
       "same.txt"},
  };
  for (const auto& [args, what] : synth) {
    SCOPED_TRACE(args);
    const CliRun r = run("synth " + args + " -o " + part.string());
    EXPECT_EQ(r.code, 2);
    EXPECT_NE(r.err.find(what), std::string::npos) << r.err;
    EXPECT_EQ(std::count(r.err.begin(), r.err.end(), '\n'), 1) << r.err;
    EXPECT_FALSE(fs::exists(part));
  }
}

// Row 14: an output path that cannot be written is refused before any work: the one line on
// stderr is the refusal, no progress line came before it.
TEST_F(Reliability, UnusableOutputIsRefusedBeforeAnyWork) {
  const fs::path regular = file("occupied", "not a folder");
  for (const std::string& o : {regular.string(), std::string("/proc/flank-x"), std::string("''")}) {
    SCOPED_TRACE(o);
    for (const std::string& cmd : {"decompose " + mesh_.string(), "fit " + mesh_.string() + " " + kLine}) {
      const CliRun r = run(cmd + " -o " + o);
      EXPECT_EQ(r.code, 2);
      EXPECT_EQ(std::count(r.err.begin(), r.err.end(), '\n'), 1) << r.err;
      EXPECT_EQ(r.err.find("read "), std::string::npos) << r.err;
    }
  }
  EXPECT_EQ(slurp(regular), "not a folder");
  for (const std::string& o : {regular.parent_path().string(), std::string("/proc/flank-x/x.stl"), std::string("''")}) {
    const CliRun r = run("synth --guides seed003 --tool cylinder:5 -o " + o);
    EXPECT_EQ(r.code, 2) << o;
    EXPECT_EQ(std::count(r.err.begin(), r.err.end(), '\n'), 1) << r.err;
  }
}

// Row 15: a path with a newline or control bytes stays one line on the terminal, escaped.
TEST_F(Reliability, ControlCharactersAreNotEchoed) {
  const CliRun r = run("info \"" + dir_.string() + "/$(printf 'a\\nb\\033[31m.stl')\"");
  EXPECT_EQ(r.code, 2);
  EXPECT_EQ(std::count(r.err.begin(), r.err.end(), '\n'), 1) << r.err;
  EXPECT_EQ(r.err.find('\x1b'), std::string::npos) << r.err;
  EXPECT_NE(r.err.find("a\\nb\\x1b[31m.stl"), std::string::npos) << r.err;
}

}  // namespace
