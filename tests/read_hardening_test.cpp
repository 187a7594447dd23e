// Issue 14, the read side: every file flank reads (MESH, --lines, --motion) is refused with
// one line naming it when it is not a regular file, too large, a lie about its own counts, or
// has polygons or lines that no real part has; duplicate faces read as the part itself.
#include <fcntl.h>
#include <gtest/gtest.h>
#include <sys/stat.h>
#include <sys/wait.h>
#include <unistd.h>

#include <algorithm>
#include <array>
#include <atomic>
#include <chrono>
#include <cmath>
#include <cstdint>
#include <cstdlib>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <functional>
#include <numbers>
#include <random>
#include <sstream>
#include <string>
#include <thread>
#include <vector>

#include "io/read_file.h"
#include "io/read_lines.h"
#include "io/read_mesh.h"
#include "kernels/parallel.h"
#include "solver/synth.h"
#include "tests/test_files.h"

namespace flank::io {
namespace {

namespace fs = std::filesystem;

// A file of tests/data.
std::string data_file(const std::string& name) { return FLANK_TEST_DATA_DIR "/" + name; }

using testing::slurp;
using testing::put_u32;

// The message of the io::Error that `read` throws, or "" when it throws none.
std::string error_of(const std::function<void()>& read) {
  try {
    read();
  } catch (const Error& e) {
    return e.what();
  }
  return "";
}

struct FlankRun {
  int code = -1;
  std::string err;
};

// The flank binary with `args`, killed after 20 s (a blocked read must fail the test, not hang).
FlankRun flank(const std::vector<std::string>& args, const fs::path& scratch) {
  std::string command = "timeout 20 '" FLANK_BINARY "'";
  for (const std::string& a : args) command += " '" + a + "'";  // our paths hold no quote
  const fs::path err = scratch / "stderr.txt";
  command += " >/dev/null 2>'" + err.string() + "'";
  const int status = std::system(command.c_str());
  return {WIFEXITED(status) ? WEXITSTATUS(status) : -1, slurp(err)};
}

// A binary STL of `records` (50 bytes each) whose header claims `count` triangles.
std::string binary_stl(const std::string& records, std::uint32_t count) {
  std::string s(80, ' ');
  put_u32(s, count);
  return s + records;
}

// The 50-byte record of the triangle with these corners, its normal left zero.
std::string stl_record(const std::array<std::array<float, 3>, 3>& corners) {
  std::string s(12, '\0');
  for (const auto& c : corners)
    for (float x : c) {
      std::uint32_t bits;
      std::memcpy(&bits, &x, 4);
      put_u32(s, bits);
    }
  return s + std::string(2, '\0');
}

// The record with its corners in the order (0, 2, 1): the same face, reversed.
std::string reversed_record(const std::string& record) {
  std::string s = record;
  s.replace(12 + 12, 12, record.substr(12 + 24, 12));
  s.replace(12 + 24, 12, record.substr(12 + 12, 12));
  return s;
}

// Each test's own scratch folder, emptied before and removed after.
class ReadHardening : public ::testing::Test {
 protected:
  const fs::path dir_ = fs::temp_directory_path() /
                        ("flank_read_hardening_" + std::to_string(::getpid()) + "_" +
                         ::testing::UnitTest::GetInstance()->current_test_info()->name());
  ReadHardening() { fs::remove_all(dir_), fs::create_directories(dir_); }
  ~ReadHardening() override { fs::remove_all(dir_); }
  std::string write(const std::string& name, const std::string& content) const {
    std::ofstream(dir_ / name, std::ios::binary) << content;
    return (dir_ / name).string();
  }
};

// Row 5. A FIFO would block the reader and /dev/zero never ends: each is refused from stat,
// before it is opened for reading, by every reader and by the command line.
TEST_F(ReadHardening, NonRegularFilesAreRefusedAtOnce) {
  const std::string fifo = (dir_ / "mesh.stl").string();
  ASSERT_EQ(::mkfifo(fifo.c_str(), 0600), 0);
  // Should a reader open the FIFO and block, a writer comes and goes so that it returns
  // (with the wrong message) instead of hanging the test.
  std::atomic<bool> done{false};
  std::thread unblock([&] {
    while (!done) {
      const int fd = ::open(fifo.c_str(), O_WRONLY | O_NONBLOCK);
      if (fd >= 0) ::close(fd);
      std::this_thread::sleep_for(std::chrono::milliseconds(20));
    }
  });
  std::vector<std::string> paths = {fifo};
  for (const char* device : {"/dev/zero", "/dev/urandom", "/dev/null"})
    if (fs::exists(device)) paths.push_back(device);
  for (const std::string& path : paths) {
    SCOPED_TRACE(path);
    const std::string expected = path + ": not a regular file";
    EXPECT_EQ(error_of([&] { read_mesh(path); }), expected);
    EXPECT_EQ(error_of([&] { read_lines_file(path); }), expected);
    EXPECT_EQ(error_of([&] { read_motion_file(path); }), expected);
  }
  done = true;
  unblock.join();

  const std::string cube = data_file("cube_ascii.stl");
  for (const std::vector<std::string>& args :
       {std::vector<std::string>{"info", fifo}, {"info", "/dev/zero"},
        {"fit", cube, "--lines", fifo, "-o", (dir_ / "out").string()},
        {"fit", cube, "--lines", "/dev/urandom", "-o", (dir_ / "out").string()},
        {"synth", "--motion", fifo, "--tool", "cylinder:5", "-o", (dir_ / "x.stl").string()}}) {
    const FlankRun r = flank(args, dir_);
    EXPECT_EQ(r.code, 2) << args[0] << " " << args[1] << ": " << r.err;
    EXPECT_NE(r.err.find(": not a regular file\n"), std::string::npos) << r.err;
    EXPECT_EQ(std::count(r.err.begin(), r.err.end(), '\n'), 1) << r.err;
  }
  EXPECT_FALSE(fs::exists(dir_ / "out"));
  EXPECT_FALSE(fs::exists(dir_ / "x.stl"));
}

// The in-memory entry point is what read_mesh parses: same mesh, same report.
TEST_F(ReadHardening, BytesReadAsTheFile) {
  for (const char* name : {"cube_ascii.stl", "cube_quads.obj", "cube_ascii.ply"}) {
    const std::string path = data_file(name);
    const LoadedMesh file = read_mesh(path);
    const LoadedMesh bytes = read_mesh_bytes(path, slurp(path));
    EXPECT_EQ(file.mesh.V, bytes.mesh.V) << name;
    EXPECT_EQ(file.mesh.F, bytes.mesh.F) << name;
    EXPECT_EQ(file.report.format, bytes.report.format) << name;
  }
  EXPECT_EQ(error_of([] { read_mesh_bytes("x.obj", "v 0 0 0\nf 1 1\n"); }).rfind("x.obj: ", 0), 0u);
}

// A file is read whole and byte for byte, in pieces side by side when it is large: sizes
// around the pieces' bounds, at one thread and at two; a file whose size says 0 (/proc) is
// read to its end; one larger than the limit is refused, before and while it is read.
TEST_F(ReadHardening, FilesAreReadByteForByte) {
  std::mt19937 rng(5);
  for (const std::size_t size : {std::size_t{0}, std::size_t{1}, std::size_t{65536},
                                 std::size_t{1} << 20, (std::size_t{3} << 20) + 7}) {
    std::string content(size, '\0');
    for (char& c : content) c = static_cast<char>(rng());
    const std::string path = write("bytes.bin", content);
    for (const int threads : {1, 2}) {
      const ThreadLimit limit(threads);
      const FileBytes read = read_regular_file(path, std::uint64_t{1} << 30);
      EXPECT_EQ(read.size(), size) << threads << " threads";
      EXPECT_TRUE(read.view() == content) << size << " bytes, " << threads << " threads";
    }
  }
  const FileBytes status = read_regular_file("/proc/self/status", 1 << 20);
  EXPECT_EQ(status.view().substr(0, 5), "Name:");
  const std::string big = write("big.bin", std::string(100, 'x'));
  EXPECT_EQ(error_of([&] { read_regular_file(big, 50); }),
            big + ": file too large (100 bytes; flank reads at most 50)");
  EXPECT_EQ(error_of([] { read_regular_file("/proc/self/status", 16); }),
            "/proc/self/status: file too large (more than 16 bytes)");
}

// Row 6. 20 MB of binary 255-gons on uchar indices would make 20.7 M triangles (2.5 GB): the
// face list is counted before anything is allocated for it.
TEST_F(ReadHardening, TriangleBudgetIsCheckedBeforeAllocating) {
  const int faces = 20 << 20 >> 8;  // 256 bytes each: a count and 255 indices
  std::string ply = "ply\nformat binary_little_endian 1.0\nelement vertex 255\n"
                    "property float x\nproperty float y\nproperty float z\nelement face " +
                    std::to_string(faces) + "\nproperty list uchar uchar vertex_indices\nend_header\n";
  for (int i = 0; i < 255; ++i) {
    const float angle = static_cast<float>(2 * std::numbers::pi * i / 255);
    const float xyz[3] = {std::cos(angle), std::sin(angle), 0.0f};
    ply.append(reinterpret_cast<const char*>(xyz), sizeof xyz);
  }
  std::string face(256, '\0');
  face[0] = static_cast<char>(255);
  for (int i = 0; i < 255; ++i) face[1 + i] = static_cast<char>(i);
  ply.reserve(ply.size() + 256 * static_cast<std::size_t>(faces));
  for (int f = 0; f < faces; ++f) ply += face;
  const auto start = std::chrono::steady_clock::now();
  EXPECT_EQ(error_of([&] { read_mesh_bytes("gons.ply", ply); }),
            "gons.ply: " + std::to_string(253 * faces) +
                " triangles after splitting polygons, more than flank's limit of 10000000 triangles");
  // A count pass, not a read: well under a second even in a sanitizer build.
  EXPECT_LT(std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count(), 5.0);

  // Counts that the file cannot hold are refused before anything is reserved.
  const std::string header = "ply\nformat ascii 1.0\nelement vertex 2147483648\nproperty float x\n"
                             "property float y\nproperty float z\nend_header\n";
  EXPECT_EQ(error_of([&] { read_mesh_bytes("claim.ply", header + std::string(1000, '0')); }),
            "claim.ply: truncated PLY (expected 2147483648 vertex rows, file holds at most 166)");
  std::string binary = header;
  binary.replace(binary.find("ascii"), 5, "binary_little_endian");
  EXPECT_EQ(error_of([&] { read_mesh_bytes("claim.ply", binary + std::string(1000, '\0')); }),
            "claim.ply: truncated binary PLY (expected 2147483648 vertex rows, file holds at most 83)");
  EXPECT_EQ(error_of([] { read_mesh_bytes("claim.stl", binary_stl(std::string(50, '\0'), 0xffffffffu)); }),
            "claim.stl: truncated binary STL (expected 4294967295 triangles, file holds 1)");
  const std::string faces_claim =
      "ply\nformat ascii 1.0\nelement vertex 3\nproperty float x\nproperty float y\n"
      "property float z\nelement face 4000000000\nproperty list uchar int vertex_indices\n"
      "end_header\n0 0 0\n1 0 0\n0 1 0\n3 0 1 2\n";
  EXPECT_NE(error_of([&] { read_mesh_bytes("faces.ply", faces_claim); }).find("truncated PLY"),
            std::string::npos);
}

// Row 8. 10,000 copies of one triangle (80 KB), in every corner order and orientation, read
// as that triangle, and `flank info` says how many were dropped.
TEST_F(ReadHardening, DuplicateFacesAreDroppedAndCounted) {
  std::string obj = "v 0 0 0\nv 1 0 0\nv 0 1 0\n";
  const char* orders[] = {"f 1 2 3\n", "f 2 3 1\n", "f 3 1 2\n", "f 1 3 2\n", "f 3 2 1\n", "f 2 1 3\n"};
  for (int i = 0; i < 10000; ++i) obj += orders[i % 6];
  const std::string path = write("copies.obj", obj);
  const LoadedMesh m = read_mesh(path);
  EXPECT_EQ(m.report.input_faces, 10000);
  EXPECT_EQ(m.report.duplicate_faces, 9999);
  ASSERT_EQ(m.mesh.face_count(), 1);
  EXPECT_EQ(m.mesh.F.row(0), Eigen::RowVector3i(0, 1, 2));  // the first copy, as written
  EXPECT_EQ(m.report.non_manifold_edges, 0);

  const std::string stdout_file = (dir_ / "info.txt").string();
  const std::string command = std::string("'" FLANK_BINARY "' info '") + path + "' >'" + stdout_file + "'";
  ASSERT_EQ(std::system(command.c_str()), 0);
  EXPECT_NE(slurp(stdout_file).find("duplicates dropped: 9999"), std::string::npos) << slurp(stdout_file);

  // Faces on welded vertices are duplicates too: an STL repeats its coordinates.
  const std::string record = stl_record({{{0, 0, 0}, {1, 0, 0}, {0, 1, 0}}});
  const LoadedMesh stl = read_mesh_bytes("two.stl", binary_stl(record + reversed_record(record), 2));
  EXPECT_EQ(stl.mesh.face_count(), 1);
  EXPECT_EQ(stl.report.duplicate_faces, 1);
}

// Row 9. Every face of a real part written twice (interleaved and reversed, or the whole
// file again) reads as exactly the clean part: same vertices, same faces, same order.
TEST_F(ReadHardening, DuplicatedPartReadsAsTheCleanPart) {
  const std::string clean_bytes = slurp(data_file("hecc_splitter_blade_side_a.stl"));
  const std::string records = clean_bytes.substr(84);
  const auto count = static_cast<std::uint32_t>(records.size() / 50);
  std::string interleaved, rotated;
  for (std::size_t t = 0; t < count; ++t) {
    const std::string r = records.substr(50 * t, 50);
    interleaved += r + reversed_record(r);
    // The same corners starting from the second one: same face, same orientation.
    rotated += r.substr(0, 12) + r.substr(24, 24) + r.substr(12, 12) + r.substr(48);
  }
  const LoadedMesh clean = read_mesh_bytes("clean.stl", clean_bytes);
  ASSERT_EQ(clean.report.duplicate_faces, 0);
  for (const auto& [name, bytes] :
       {std::pair<std::string, std::string>{"interleaved.stl", binary_stl(interleaved, 2 * count)},
        {"twice.stl", binary_stl(records + rotated, 2 * count)}}) {
    SCOPED_TRACE(name);
    const LoadedMesh twice = read_mesh_bytes(name, bytes);
    EXPECT_EQ(twice.report.duplicate_faces, static_cast<int>(count));
    EXPECT_EQ(twice.report.input_faces, 2 * static_cast<int>(count));
    EXPECT_EQ(twice.mesh.V, clean.mesh.V);
    EXPECT_EQ(twice.mesh.F, clean.mesh.F);
    EXPECT_EQ(twice.report.non_manifold_edges, clean.report.non_manifold_edges);
    EXPECT_EQ(twice.report.boundary_edges, clean.report.boundary_edges);
    EXPECT_EQ(twice.report.orientable, clean.report.orientable);
  }

  // An indexed part with its face list repeated, reversed.
  const std::string cube = slurp(data_file("cube_quads.obj"));
  std::string reversed;
  std::istringstream lines(cube);
  for (std::string line; std::getline(lines, line);) {
    if (line.rfind("f ", 0) != 0) continue;
    std::istringstream words(line.substr(2));
    std::vector<std::string> corners;
    for (std::string w; words >> w;) corners.push_back(w);
    // Reversed from the same first corner: the same fan, each triangle reversed. (From another
    // corner a quad's fan takes the other diagonal: those triangles are not duplicates.)
    reversed += "f " + corners[0];
    for (auto it = corners.rbegin(); it + 1 != corners.rend(); ++it) reversed += " " + *it;
    reversed += "\n";
  }
  const LoadedMesh clean_cube = read_mesh_bytes("cube.obj", cube);
  const LoadedMesh double_cube = read_mesh_bytes("cube.obj", cube + reversed);
  EXPECT_EQ(double_cube.report.duplicate_faces, 12);
  EXPECT_EQ(double_cube.mesh.V, clean_cube.mesh.V);
  EXPECT_EQ(double_cube.mesh.F, clean_cube.mesh.F);
}

// Copies are found from the edges' runs (a copy shares each edge, and the vertex off it, with
// its first): on an edge of two faces, at a boundary, and on a fin's edge of three faces or
// more. Faces that share an edge and differ in their third vertex are not copies, nor are a
// fin's faces on one edge.
TEST_F(ReadHardening, CopiesAreFoundOnEveryKindOfEdge) {
  // Two triangles of a square, a fin standing on their diagonal (1-3), a flap on edge 1-2.
  const std::string points = "v 0 0 0\nv 1 0 0\nv 1 1 0\nv 0 1 0\nv 0.5 0.5 1\nv 1 0.5 -1\n";
  const std::string faces = "f 1 2 3\nf 1 3 4\nf 1 3 5\nf 2 6 3\n";
  const LoadedMesh clean = read_mesh_bytes("clean.obj", points + faces);
  ASSERT_EQ(clean.mesh.face_count(), 4);
  EXPECT_EQ(clean.report.duplicate_faces, 0);
  EXPECT_EQ(clean.report.non_manifold_edges, 1);
  for (const std::string copy : {"f 3 2 1\n", "f 4 1 3\n", "f 5 3 1\n", "f 3 6 2\n"}) {
    SCOPED_TRACE(copy);
    for (const std::string& file : {points + faces + copy, points + copy + faces}) {
      const LoadedMesh read = read_mesh_bytes("copy.obj", file);
      EXPECT_EQ(read.report.duplicate_faces, 1);
      EXPECT_EQ(read.report.input_faces, 5);
      EXPECT_EQ(read.mesh.V, clean.mesh.V);
      EXPECT_EQ(read.report.non_manifold_edges, clean.report.non_manifold_edges);
      EXPECT_EQ(read.report.boundary_edges, clean.report.boundary_edges);
    }
    EXPECT_EQ(read_mesh_bytes("copy.obj", points + faces + copy).mesh.F, clean.mesh.F);
  }
  // The fin three times: its copies' every edge has three faces or more.
  const LoadedMesh fins = read_mesh_bytes("fins.obj", points + faces + "f 3 5 1\nf 1 5 3\n");
  EXPECT_EQ(fins.report.duplicate_faces, 2);
  EXPECT_EQ(fins.mesh.F, clean.mesh.F);
  // Every face twice, one of them a third time.
  const LoadedMesh thrice = read_mesh_bytes("thrice.obj", points + faces + faces + "f 3 5 1\n");
  EXPECT_EQ(thrice.report.duplicate_faces, 5);
  EXPECT_EQ(thrice.mesh.F, clean.mesh.F);
}

// A regular polygon of n vertices as an OBJ face (or, when `ply`, a binary PLY face).
std::string polygon_file(int n, bool ply) {
  std::string s = ply ? "ply\nformat binary_little_endian 1.0\nelement vertex " + std::to_string(n) +
                            "\nproperty float x\nproperty float y\nproperty float z\n"
                            "element face 1\nproperty list uint uint vertex_indices\nend_header\n"
                      : "";
  std::string face = ply ? "" : "f";
  for (int i = 0; i < n; ++i) {
    const double angle = 2 * std::numbers::pi * i / n;
    if (ply) {
      const float xyz[3] = {static_cast<float>(std::cos(angle)), static_cast<float>(std::sin(angle)), 0};
      s.append(reinterpret_cast<const char*>(xyz), sizeof xyz);
      put_u32(face, static_cast<std::uint32_t>(i));
    } else {
      // Appended piece by piece: GCC 12 warns (-Wrestrict, falsely) on "v " + std::string.
      s.append("v ").append(std::to_string(std::cos(angle))).append(" ");
      s.append(std::to_string(std::sin(angle))).append(" 0\n");
      face.append(" ").append(std::to_string(i + 1));
    }
  }
  if (!ply) return s + face + "\n";
  std::string count;
  put_u32(count, static_cast<std::uint32_t>(n));
  return s + count + face;
}

// Row 10. A 200k-vertex polygon (a fan of slivers that made decompose run > 240 s) is
// refused at once, naming the face, and `flank info` says so quickly.
TEST_F(ReadHardening, PolygonsBeyondTheLimitAreRefused) {
  const std::string expected = ": face 1 has 200000 vertices (flank's limit is 1000 per polygon)";
  EXPECT_EQ(error_of([] { read_mesh_bytes("fan.obj", polygon_file(200000, false)); }),
            "fan.obj" + expected + " (line 200001)");
  EXPECT_EQ(error_of([] { read_mesh_bytes("fan.ply", polygon_file(200000, true)); }),
            "fan.ply: face 0 has 200000 vertices (flank's limit is 1000 per polygon)");
  std::string stl = "solid fan\nfacet normal 0 0 1\nouter loop\n";
  for (int i = 0; i <= kMaxPolygonVertices; ++i) stl += "vertex " + std::to_string(i) + " 0 0\n";
  EXPECT_NE(error_of([&] { read_mesh_bytes("fan.stl", stl + "endloop\nendfacet\n"); })
                .find("facet 1 has more than 1000 vertices (flank's limit per polygon)"),
            std::string::npos);

  // At the limit the polygon reads: a planar CAD face with many segments is real.
  EXPECT_EQ(read_mesh_bytes("ok.obj", polygon_file(kMaxPolygonVertices, false)).mesh.face_count(),
            kMaxPolygonVertices - 2);
  EXPECT_NE(error_of([] { read_mesh_bytes("over.obj", polygon_file(kMaxPolygonVertices + 1, false)); }),
            "");

  const std::string path = write("fan.obj", polygon_file(200000, false));
  const auto start = std::chrono::steady_clock::now();
  const FlankRun r = flank({"info", path}, dir_);
  EXPECT_EQ(r.code, 2);
  EXPECT_NE(r.err.find("fan.obj" + expected), std::string::npos) << r.err;
  EXPECT_EQ(std::count(r.err.begin(), r.err.end(), '\n'), 1) << r.err;
  EXPECT_LT(std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count(), 10.0);
}

// Rows 13 and 15. Lines or motion rows that all lie on one axis sweep nothing and are refused
// naming the file; bytes from a --lines or --motion file never reach the terminal raw.
TEST_F(ReadHardening, LinesFilesThatBuildNoMotionAreRefused) {
  EXPECT_EQ(error_of([] { parse_lines_text("same.txt", "1 2 3 4 5 6\n1 2 3 4 5 6\n1,2,3,4,5,6\n"); }),
            "same.txt: all 3 lines lie on one straight line; a motion needs axes that sweep "
            "across the surface");
  EXPECT_EQ(error_of([] { parse_motion_text("same.txt", "0 0 0 0 0 1\n0 0 0 0 0 1\n0 0 0 0 0 1\n0 0 0 0 0 1\n"); }),
            "same.txt: all 4 control point rows lie on one straight line; a motion needs axes that "
            "sweep across the surface");
  // Sliding along the axis, or stretching it, is no sweep either.
  EXPECT_NE(error_of([] { parse_lines_text("slide.txt", "0 0 0 0 0 1\n0 0 1 0 0 2\n0 0 -5 0 0 9\n"); })
                .find("one straight line"),
            std::string::npos);
  const std::vector<AxisRow> ok =
      parse_lines_text("ok.txt", "# tip, spindle\n0,0,0, 0,0,10\n\n 1 0 0 1 0 10 # next\n");
  ASSERT_EQ(ok.size(), 2u);
  EXPECT_EQ(ok[1].a, Vec3(1, 0, 0));
  EXPECT_EQ(ok[1].line, 4);
  EXPECT_EQ(error_of([] { parse_lines_text("one.txt", "0 0 0 0 0 1\n"); }),
            "one.txt: needs at least two lines, in motion order");
  EXPECT_EQ(error_of([] { parse_lines_text("hex.txt", "0 0 0 0 0 1\n0x10 0 0 0 0 1\n"); }),
            "hex.txt: line 2: '0x10' is not a finite number");

  const std::string escape = "0 0 0 0 0 1\n\x1b[2J\x1b]0;owned\x07 0 0 0 0 1\n";
  const std::string lines_message = error_of([&] { parse_lines_text("esc.txt", escape); });
  const std::string motion_message = error_of([&] { parse_motion_text("esc.txt", escape); });
  for (const std::string& message : {lines_message, motion_message}) {
    EXPECT_EQ(message, "esc.txt: line 2: '?[2J?]0;owned?' is not a finite number");
    for (const char c : message) EXPECT_TRUE(c >= 0x20 && c < 0x7f) << message;
  }

  // The command line: one clean line, exit 2.
  const std::string cube = data_file("cube_ascii.stl");
  for (const std::string& text : {std::string("1 2 3 4 5 6\n1 2 3 4 5 6\n"), escape}) {
    const FlankRun r = flank({"fit", cube, "--lines", write("lines.txt", text), "-o", (dir_ / "out").string()}, dir_);
    EXPECT_EQ(r.code, 2) << r.err;
    EXPECT_NE(r.err.find("lines.txt: "), std::string::npos) << r.err;
    EXPECT_EQ(std::count(r.err.begin(), r.err.end(), '\n'), 1) << r.err;
    EXPECT_EQ(r.err.find('\x1b'), std::string::npos) << r.err;
    EXPECT_FALSE(fs::exists(dir_ / "out"));
  }
}

// Row 16. A binary STL holding more triangles than its header says is refused naming both
// counts (reading only the count would drop part of the surface); a tail shorter than one
// record holds no triangle and is tolerated.
TEST_F(ReadHardening, BinaryStlCountMustMatchTheFile) {
  std::string records;
  for (int t = 0; t < 12; ++t)
    records += stl_record({{{0, 0, static_cast<float>(t)}, {1, 0, static_cast<float>(t)}, {0, 1, static_cast<float>(t)}}});
  EXPECT_EQ(error_of([&] { read_mesh_bytes("half.stl", binary_stl(records, 6)); }),
            "half.stl: binary STL header says 6 triangles but the file holds 12 (684 bytes)");
  EXPECT_EQ(error_of([&] { read_mesh_bytes("none.stl", binary_stl(records, 0)); }),
            "none.stl: binary STL header says 0 triangles but the file holds 12 (684 bytes)");
  EXPECT_EQ(read_mesh_bytes("padded.stl", binary_stl(records + "pad", 12)).mesh.face_count(), 12);
  EXPECT_NE(error_of([&] { read_mesh_bytes("long.stl", binary_stl(records, 13)); }).find("truncated"),
            std::string::npos);
}

}  // namespace
}  // namespace flank::io
