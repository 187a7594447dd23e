// The flank command line as a machinist meets it: bad input gets one line naming the file
// and the problem, a non-zero exit, and no output file; a good run writes every output.
#include <gtest/gtest.h>

#include "tests/cli_run.h"

#include <unistd.h>

#include <algorithm>
#include <array>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <string>

namespace {

using namespace flank::cli_test;

TEST_F(Cli, BadMeshesGiveOneLineAndNoOutput) {
  const fs::path out = dir_ / "results";
  const std::array<std::pair<std::string, std::string>, 6> cases{{
      {"empty.stl", ""},
      {"truncated.stl", std::string(80, 'x') + std::string("\x10\x00\x00\x00", 4) + std::string(60, '\0')},
      {"nan.obj", "v 0 0 0\nv 1 0 nan\nv 0 1 0\nf 1 2 3\n"},
      {"range.obj", "v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 9\n"},
      {"degenerate.obj", "v 0 0 0\nv 1 0 0\nv 2 0 0\nf 1 2 3\n"},
      {"garbage.ply", "ply\nformat ascii 1.0\nelement vertex 3\nproperty float x\nend_header\n1\n"},
  }};
  for (const auto& [name, content] : cases) {
    const fs::path mesh = file(name, content);
    expect_clean_failure(run("fit " + mesh.string() + " " + kLine + " -o " + out.string()), name, out);
  }
  expect_clean_failure(run("fit " + (dir_ / "missing.stl").string() + " " + kLine + " -o " + out.string()),
                       "missing.stl", out);
}

TEST_F(Cli, ImpossibleOptionsAreRefused) {
  const fs::path out = dir_ / "results";
  const fs::path mesh = dir_ / "part.stl";
  ASSERT_EQ(run("synth --guides seed003 --tool cylinder:5 --resolution 61x21 -o " + mesh.string()).code, 0);
  expect_clean_failure(run("fit " + mesh.string() + " -o " + out.string()), "--line", out);
  expect_clean_failure(run("fit " + mesh.string() + " " + kLine + " --tool ballnose -o " + out.string()), "ballnose", out);
  expect_clean_failure(run("fit " + mesh.string() + " " + kLine + " --tolerance -1 -o " + out.string()), "tolerance", out);
  expect_clean_failure(run("fit " + mesh.string() + " " + kLine + " --tolerance 0.1 --tolerance-rel 1e-4 -o " + out.string()),
                       "tolerance", out);
  expect_clean_failure(run("fit " + mesh.string() + " --line 1,2,3 -o " + out.string()), "--line", out);
  expect_clean_failure(run("fit " + mesh.string() + " " + kLine + " --holder 10 -o " + out.string()), "--holder", out);
  expect_clean_failure(run("synth --guides seed003 --tool cone:4 -o " + (dir_ / "x.stl").string()), "cone", out);
  EXPECT_FALSE(fs::exists(dir_ / "x.stl"));
  expect_clean_failure(run("fit " + mesh.string() + " --lines " + file("l.txt", "1 2 3 4 5 6\n").string() +
                           " -o " + out.string()),
                       "l.txt", out);
}

TEST_F(Cli, FitWritesEveryOutput) {
  const fs::path mesh = dir_ / "part.stl";
  ASSERT_EQ(run("synth --guides seed003 --tool cylinder:5 --resolution 121x31 -o " + mesh.string()).code, 0);
  const fs::path out = dir_ / "results";
  const CliRun r = run("fit " + mesh.string() + " " + kLine + " --tool cylinder --tolerance-rel 5e-4 --holder 30,8 -q -o " +
                    out.string());
  ASSERT_EQ(r.code, 0) << r.err;
  for (const char* name : {"report.html", "patches.json", "envelopes.ply", "design.ply", "toolpath.apt"})
    EXPECT_GT(fs::file_size(out / name), 100u) << name;
  EXPECT_NE(r.out.find("results in " + out.string() + ": report.html patches.json"), std::string::npos) << r.out;
  std::ifstream json(out / "patches.json");
  const std::string text(std::istreambuf_iterator<char>(json), {});
  EXPECT_NE(text.find("\"flank-patches/1\""), std::string::npos);
  EXPECT_NE(text.find("\"cylinder\""), std::string::npos);
  std::ifstream apt(out / "toolpath.apt");
  const std::string cl(std::istreambuf_iterator<char>(apt), {});
  EXPECT_NE(cl.find("MULTAX"), std::string::npos);
  EXPECT_NE(cl.find("GOTO/"), std::string::npos);
  // Nothing temporary is left behind.
  for (const auto& e : fs::directory_iterator(out)) EXPECT_EQ(e.path().filename().string().rfind(".tmp", 0), std::string::npos);
  // info and movability speak too.
  const CliRun info = run("info " + mesh.string());
  EXPECT_EQ(info.code, 0);
  EXPECT_NE(info.out.find("components      1\n"), std::string::npos) << info.out;  // counted
  const CliRun m = run("movability " + mesh.string() + " " + kLine);
  EXPECT_EQ(m.code, 0);
  EXPECT_NE(m.out.find("movability"), std::string::npos);
}

// patches.json without its timing_s block.
std::string without_timing(const fs::path& json) {
  std::ifstream in(json);
  std::string text(std::istreambuf_iterator<char>(in), {});
  const auto begin = text.find("\"timing_s\"");
  const auto end = text.find('}', begin);
  if (begin != std::string::npos && end != std::string::npos) text.erase(begin, end - begin + 1);
  return text;
}

TEST_F(Cli, SameResultWhateverTheThreadCount) {
  const fs::path mesh = dir_ / "part.stl";
  ASSERT_EQ(run("synth --guides seed003 --tool cone:4,7 --resolution 121x31 -o " + mesh.string()).code, 0);
  std::string json[2];
  for (int threads : {1, 2}) {
    const fs::path out = dir_ / ("t" + std::to_string(threads));
    const CliRun r = run("fit " + mesh.string() + " " + kLine + " --tolerance-rel 5e-4 -q --threads " +
                         std::to_string(threads) + " -o " + out.string());
    ASSERT_EQ(r.code, 0) << r.err;
    json[threads - 1] = without_timing(out / "patches.json");
  }
  EXPECT_EQ(json[0], json[1]);
  EXPECT_GT(json[0].size(), 1000u);
}

TEST_F(Cli, DecomposeReportsNothingFoundAndRefusesImpossibleOptions) {
  const fs::path mesh = dir_ / "part.stl";
  ASSERT_EQ(run("synth --guides seed003 --tool cylinder:5 --resolution 61x21 -o " + mesh.string()).code, 0);
  const fs::path out = dir_ / "results";
  // A tolerance no cutter can meet: a clear report with zero patches, exit 0.
  const CliRun none = run("decompose " + mesh.string() + " --tolerance 1e-9 --tool cylinder -q -o " + out.string());
  EXPECT_EQ(none.code, 0) << none.err;
  EXPECT_NE(none.out.find("0 patches"), std::string::npos) << none.out;
  EXPECT_NE(none.out.find("no patch meets the tolerance"), std::string::npos) << none.out;
  EXPECT_TRUE(fs::exists(out / "patches.json"));
  const fs::path out2 = dir_ / "results2";
  expect_clean_failure(run("decompose " + mesh.string() + " --radius 5,1 -o " + out2.string()), "--radius", out2);
  expect_clean_failure(run("decompose " + mesh.string() + " --tool cone,drill -o " + out2.string()), "drill", out2);
  expect_clean_failure(run("decompose " + mesh.string() + " --length 0,10 -o " + out2.string()), "--length", out2);
  expect_clean_failure(run("fit " + mesh.string() + " " + kLine + " --radius 5,1 -o " + out2.string()), "--radius", out2);
}

// A run says what each patch is and buys: its cutter kind, the coverage after 1..k patches on
// stdout and in patches.json, and what is left for ball-end finishing.
TEST_F(Cli, DecomposeShowsTheTradeOff) {
  const fs::path mesh = dir_ / "part.stl";
  ASSERT_EQ(run("synth --guides seed003 --tool cylinder:5 --resolution 61x21 -o " + mesh.string()).code, 0);
  const fs::path out = dir_ / "results";
  const CliRun r = run("decompose " + mesh.string() + " --tool cylinder,cone --tolerance-rel 3e-4 -q -o " + out.string());
  ASSERT_EQ(r.code, 0) << r.err;
  EXPECT_NE(r.out.find("1 patch cover"), std::string::npos) << r.out;
  EXPECT_NE(r.out.find("patch 0: cylinder cutter"), std::string::npos) << r.out;
  EXPECT_NE(r.out.find("coverage after 1..1 patches:"), std::string::npos) << r.out;
  EXPECT_NE(r.out.find("ball-end finishing"), std::string::npos) << r.out;
  EXPECT_EQ(r.out.find("finishing: -"), std::string::npos) << r.out;  // no negative areas
  std::ifstream json(out / "patches.json");
  const std::string text(std::istreambuf_iterator<char>(json), {});
  for (const char* key : {"\"curve\"", "\"uncovered_regions\"", "\"noise_sigma\"", "\"max_gouge\""})
    EXPECT_NE(text.find(key), std::string::npos) << key;
}

// --no-report writes no report.html, and takes away an earlier run's: a report beside
// patches.json always describes the same run.
TEST_F(Cli, NoReportLeavesNoStaleReport) {
  const fs::path mesh = dir_ / "part.stl";
  ASSERT_EQ(run("synth --guides seed003 --tool cylinder:5 --resolution 61x11 -o " + mesh.string()).code, 0);
  const fs::path out = dir_ / "results";
  const std::string fit = "fit " + mesh.string() + " " + kLine + " --tool cylinder --tolerance-rel 5e-4 -q -o " + out.string();
  ASSERT_EQ(run(fit).code, 0);
  ASSERT_TRUE(fs::exists(out / "report.html"));
  const CliRun r = run(fit + " --no-report");
  ASSERT_EQ(r.code, 0) << r.err;
  EXPECT_FALSE(fs::exists(out / "report.html"));
  EXPECT_TRUE(fs::exists(out / "patches.json"));
  EXPECT_EQ(r.out.find("report.html"), std::string::npos) << r.out;
}

TEST_F(Cli, HelpIsReadable) {
  const CliRun r = run("fit --help");
  EXPECT_EQ(r.code, 0);
  EXPECT_NE(r.out.find("--tolerance"), std::string::npos);
  EXPECT_NE(r.out.find("--holder"), std::string::npos);
  // decompose says its defaults: every cutter kind, radii and lengths relative to the part.
  const CliRun d = run("decompose --help");
  EXPECT_EQ(d.code, 0);
  EXPECT_NE(d.out.find("every kind"), std::string::npos) << d.out;
  EXPECT_NE(d.out.find("1%..10% of the diagonal"), std::string::npos) << d.out;
  EXPECT_NE(d.out.find("3%..45% of the diagonal"), std::string::npos) << d.out;
}

}  // namespace
