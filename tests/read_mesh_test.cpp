// io::read_mesh: every format reads to the same mesh, repairs are counted, bad input throws one
// line naming the file, and no prefix or garbage crashes the reader.
#include "io/read_mesh.h"

#include <gtest/gtest.h>
#include <unistd.h>

#include <algorithm>
#include <array>
#include <charconv>
#include <cmath>
#include <cstdint>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <functional>
#include <limits>
#include <map>
#include <numbers>
#include <random>
#include <sstream>
#include <string>
#include <tuple>
#include <unordered_map>
#include <utility>
#include <vector>

#include "kernels/parallel.h"
#include "tests/test_files.h"

namespace flank::io {
namespace {

namespace fs = std::filesystem;

const std::string kData = FLANK_TEST_DATA_DIR;

// Unit cube, vertex i = (i & 1, i >> 1 & 1, i >> 2 & 1), quads counter-clockwise from outside.
const std::array<std::array<int, 4>, 6> kCubeQuads = {
    {{0, 2, 3, 1}, {4, 5, 7, 6}, {0, 1, 5, 4}, {2, 6, 7, 3}, {0, 4, 6, 2}, {1, 3, 7, 5}}};

Vec3 cube_vertex(int i) { return Vec3(i & 1, (i >> 1) & 1, (i >> 2) & 1); }

std::vector<std::array<int, 3>> cube_triangles() {
  std::vector<std::array<int, 3>> out;
  for (const auto& q : kCubeQuads) {
    out.push_back({q[0], q[1], q[2]});
    out.push_back({q[0], q[2], q[3]});
  }
  return out;
}

using testing::put_u32;
void put_f32(std::string& s, float f) {
  std::uint32_t bits;
  std::memcpy(&bits, &f, 4);
  put_u32(s, bits);
}
void put_f64(std::string& s, double d) {
  std::uint64_t bits;
  std::memcpy(&bits, &d, 8);
  put_u32(s, static_cast<std::uint32_t>(bits));
  put_u32(s, static_cast<std::uint32_t>(bits >> 32));
}

// A binary STL whose header starts with "solid", as some exporters write it.
std::string cube_binary_stl(std::uint32_t claimed = 12) {
  std::string s = "solid cube written as binary";
  s.resize(80, ' ');
  put_u32(s, claimed);
  for (const auto& t : cube_triangles()) {
    for (int k = 0; k < 3; ++k) put_f32(s, 0.0f);  // normal: readers must not trust it
    for (int i : t)
      for (int k = 0; k < 3; ++k) put_f32(s, static_cast<float>(cube_vertex(i)(k)));
    s += std::string(2, '\0');
  }
  return s;
}

// Binary little-endian PLY: double coordinates, a list property to skip in the vertex
// element, faces as quads with an int count and uint indices named vertex_index.
std::string cube_binary_ply() {
  std::string s =
      "ply\r\nformat binary_little_endian 1.0\r\ncomment cube\r\nelement vertex 8\r\n"
      "property double x\r\nproperty short tag\r\nproperty double y\r\nproperty double z\r\n"
      "property list uchar ushort neighbours\r\nelement face 6\r\n"
      "property list int uint vertex_index\r\nproperty double area\r\nend_header\r\n";
  for (int i = 0; i < 8; ++i) {
    const Vec3 p = cube_vertex(i);
    put_f64(s, p.x());
    s += std::string("\x07\x00", 2);
    put_f64(s, p.y());
    put_f64(s, p.z());
    s.push_back(2);
    s += std::string("\x01\x00\x02\x00", 4);
  }
  for (const auto& q : kCubeQuads) {
    put_u32(s, 4);
    for (int i : q) put_u32(s, static_cast<std::uint32_t>(i));
    put_f64(s, 1.0);
  }
  return s;
}

// Triangles as coordinate triples, each rotated to start at its smallest corner (keeping the
// orientation), sorted: equal for two meshes that differ only in vertex numbering.
std::vector<std::array<double, 9>> canonical(const Mesh& mesh) {
  std::vector<std::array<double, 9>> out;
  for (int f = 0; f < mesh.face_count(); ++f) {
    std::array<std::array<double, 3>, 3> c;
    for (int k = 0; k < 3; ++k)
      for (int j = 0; j < 3; ++j) c[k][j] = mesh.V(mesh.F(f, k), j);
    const int first = static_cast<int>(std::min_element(c.begin(), c.end()) - c.begin());
    std::array<double, 9> t;
    for (int k = 0; k < 3; ++k)
      for (int j = 0; j < 3; ++j) t[3 * k + j] = c[(first + k) % 3][j];
    out.push_back(t);
  }
  std::sort(out.begin(), out.end());
  return out;
}

double signed_volume(const Mesh& mesh) {
  double volume = 0.0;
  for (int f = 0; f < mesh.face_count(); ++f) {
    const Vec3 a = mesh.V.row(mesh.F(f, 0)), b = mesh.V.row(mesh.F(f, 1)), c = mesh.V.row(mesh.F(f, 2));
    volume += a.dot(b.cross(c)) / 6.0;
  }
  return volume;
}

class ReadMesh : public ::testing::Test {
 protected:
  void SetUp() override {
    const auto* info = ::testing::UnitTest::GetInstance()->current_test_info();
    dir_ = fs::temp_directory_path() /
           ("flank_read_mesh_" + std::to_string(::getpid()) + "_" + info->name());
    fs::remove_all(dir_);
    fs::create_directories(dir_);
  }
  void TearDown() override { fs::remove_all(dir_); }

  std::string write(const std::string& name, const std::string& content) {
    const fs::path path = dir_ / name;
    std::ofstream(path, std::ios::binary) << content;
    return path.string();
  }

  // Reads `content` as file `name`; expects io::Error whose single-line message starts with
  // the path and contains `word`.
  void expect_error(const std::string& name, const std::string& content, const std::string& word) {
    const std::string path = write(name, content);
    try {
      read_mesh(path);
      ADD_FAILURE() << name << ": no error, expected '" << word << "'";
    } catch (const Error& e) {
      const std::string message = e.what();
      EXPECT_EQ(message.rfind(path + ": ", 0), 0u) << message;
      EXPECT_NE(message.find(word), std::string::npos) << message;
      EXPECT_EQ(message.find('\n'), std::string::npos) << message;
    }
  }

  // Reads every prefix of `content`: io::Error or a valid mesh, nothing else.
  void read_every_prefix(const std::string& name, const std::string& content) {
    for (std::size_t n = 0; n <= content.size(); ++n) {
      // A fresh name each time: truncating a file that holds data can force a synchronous
      // flush (ext4 auto_da_alloc), which makes this loop crawl.
      const std::string path = write(std::to_string(n) + "_" + name, content.substr(0, n));
      try {
        const LoadedMesh m = read_mesh(path);
        EXPECT_GT(m.mesh.face_count(), 0);
      } catch (const Error&) {
      }
      fs::remove(path);
    }
  }

  fs::path dir_;
};

void expect_unit_cube(const LoadedMesh& m) {
  EXPECT_EQ(m.mesh.vertex_count(), 8);
  EXPECT_EQ(m.mesh.face_count(), 12);
  EXPECT_EQ(m.report.components, 1);
  EXPECT_EQ(m.report.boundary_edges, 0);
  EXPECT_EQ(m.report.non_manifold_edges, 0);
  EXPECT_EQ(m.report.flipped_faces, 0);
  EXPECT_EQ(m.report.degenerate_faces, 0);
  EXPECT_TRUE(m.report.orientable);
  EXPECT_NEAR(signed_volume(m.mesh), 1.0, 1e-12);  // outward, as in the files
}

TEST_F(ReadMesh, EveryFormatReadsTheSameCube) {
  const LoadedMesh stl_ascii = read_mesh(kData + "/cube_ascii.stl");
  const LoadedMesh stl_binary = read_mesh(write("cube.stl", cube_binary_stl()));
  const LoadedMesh obj = read_mesh(kData + "/cube_quads.obj");
  const LoadedMesh ply_ascii = read_mesh(kData + "/cube_ascii.ply");
  const LoadedMesh ply_binary = read_mesh(write("cube.ply", cube_binary_ply()));
  EXPECT_EQ(stl_ascii.report.format, "stl-ascii");
  EXPECT_EQ(stl_binary.report.format, "stl-binary");
  EXPECT_EQ(obj.report.format, "obj");
  EXPECT_EQ(ply_ascii.report.format, "ply-ascii");
  EXPECT_EQ(ply_binary.report.format, "ply-binary");
  const auto reference = canonical(obj.mesh);
  for (const LoadedMesh* m : {&stl_ascii, &stl_binary, &obj, &ply_ascii, &ply_binary}) {
    SCOPED_TRACE(m->report.format);
    expect_unit_cube(*m);
    EXPECT_EQ(m->report.input_faces, 12);
    EXPECT_EQ(canonical(m->mesh), reference);
  }
  // Clean indexed formats keep the file's numbering.
  for (int i = 0; i < 8; ++i) EXPECT_EQ(Vec3(obj.mesh.V.row(i)), cube_vertex(i));
  EXPECT_EQ(obj.report.input_vertices, 8);
  EXPECT_EQ(ply_binary.report.welded_vertices, 0);
}

TEST_F(ReadMesh, FormatIsDetectedByContent) {
  // Extension-less or misnamed files: PLY by magic, ASCII and binary STL by content.
  std::ifstream in(kData + "/cube_ascii.stl");
  std::stringstream ascii;
  ascii << in.rdbuf();
  expect_unit_cube(read_mesh(write("cube_ascii.mesh", ascii.str())));
  expect_unit_cube(read_mesh(write("cube_binary", cube_binary_stl())));
  expect_unit_cube(read_mesh(write("cube.stl", cube_binary_ply())));
  expect_unit_cube(read_mesh(write("CUBE.OBJ", "v 0 0 0\nv 1 0 0\nv 1 1 0\nv 0 1 0\n"
                                               "v 0 0 1\nv 1 0 1\nv 1 1 1\nv 0 1 1\n"
                                               "f 1 4 3 2\nf 5 6 7 8\nf 1 2 6 5\n"
                                               "f 4 8 7 3\nf 1 5 8 4\nf 2 3 7 6\n")));
}

TEST_F(ReadMesh, StlIsWelded) {
  const LoadedMesh m = read_mesh(kData + "/cube_ascii.stl");
  EXPECT_EQ(m.report.input_vertices, 36);
  EXPECT_EQ(m.report.welded_vertices, 28);
  EXPECT_EQ(m.report.unused_vertices, 0);
  // Duplicated vertices in an indexed format are welded too (-0 equals +0).
  const LoadedMesh obj = read_mesh(
      write("dup.obj", "v 0 0 0\nv 1 0 0\nv 0 1 0\nv 1 -0 0\nv 1 1 0\nf 1 2 3\nf 4 5 3\n"));
  EXPECT_EQ(obj.report.welded_vertices, 1);
  EXPECT_EQ(obj.mesh.vertex_count(), 4);
  EXPECT_EQ(obj.report.boundary_edges, 4);
  EXPECT_EQ(obj.report.components, 1);
}

TEST_F(ReadMesh, DegenerateFacesAndUnusedVerticesAreDropped) {
  // A square (two triangles), a zero-area face through midpoint 5, a repeated-index face and
  // vertex 6 that no face uses.
  const LoadedMesh m = read_mesh(write("degenerate.obj",
                                       "v 0 0 0\nv 1 0 0\nv 1 1 0\nv 0 1 0\nv 0.5 0 0\nv 9 9 9\n"
                                       "f 1 2 3\nf 1 3 4\nf 1 5 2\nf 3 3 4\n"));
  EXPECT_EQ(m.report.input_faces, 4);
  EXPECT_EQ(m.report.degenerate_faces, 2);
  EXPECT_EQ(m.report.unused_vertices, 2);
  EXPECT_EQ(m.mesh.face_count(), 2);
  EXPECT_EQ(m.mesh.vertex_count(), 4);
  EXPECT_TRUE(m.mesh.F.maxCoeff() < 4 && m.mesh.F.minCoeff() >= 0);
}

// An n × n grid of unit squares in z = 0, normals +z; the triangles of the columns with
// x ≥ flip_from are written reversed.
std::string grid_obj(int n, int flip_from) {
  std::string s;
  for (int j = 0; j <= n; ++j)
    for (int i = 0; i <= n; ++i) s += "v " + std::to_string(i) + " " + std::to_string(j) + " 0\n";
  const auto id = [n](int i, int j) { return std::to_string(j * (n + 1) + i + 1); };
  for (int j = 0; j < n; ++j)
    for (int i = 0; i < n; ++i) {
      const std::string a = id(i, j), b = id(i + 1, j), c = id(i + 1, j + 1), d = id(i, j + 1);
      if (i >= flip_from)
        s += "f " + a + " " + c + " " + b + "\nf " + a + " " + d + " " + c + "\n";
      else
        s += "f " + a + " " + b + " " + c + "\nf " + a + " " + c + " " + d + "\n";
    }
  return s;
}

double min_normal_z(const Mesh& m) { return face_normals(m).col(2).minCoeff(); }
double max_normal_z(const Mesh& m) { return face_normals(m).col(2).maxCoeff(); }

TEST_F(ReadMesh, OrientationIsMadeConsistent) {
  // 2 of 8 columns reversed: 32 faces flipped back to the majority (+z).
  const LoadedMesh m = read_mesh(write("grid.obj", grid_obj(8, 6)));
  EXPECT_EQ(m.report.flipped_faces, 32);
  EXPECT_TRUE(m.report.orientable);
  EXPECT_EQ(m.report.components, 1);
  EXPECT_EQ(m.report.boundary_edges, 32);
  EXPECT_DOUBLE_EQ(min_normal_z(m.mesh), 1.0);

  // 6 of 8 columns reversed: the majority of the area now says −z, so the other 32 flip.
  const LoadedMesh majority = read_mesh(write("grid_majority.obj", grid_obj(8, 2)));
  EXPECT_EQ(majority.report.flipped_faces, 32);
  EXPECT_DOUBLE_EQ(max_normal_z(majority.mesh), -1.0);
}

// An n × n grid of unit squares (z = 0, normals +z) as a shuffled triangle soup with every
// defect the repair mends: each corner its own vertex (some at −0), every 50th triangle twice
// (its copy starting at another corner), 100 triangles on a repeated vertex, and the last
// quarter of the columns reversed. Large enough that each of the repair's sorts runs in
// pieces on two threads: the mesh and its report are the same at one thread and at two, and
// the report counts what the soup holds.
TEST_F(ReadMesh, RepairIsTheSameWhateverTheThreadCount) {
  constexpr int n = 200, flip_from = 150, copies = 2 * n * n / 50, repeated = 100;
  const auto id = [](int i, int j) { return j * (n + 1) + i; };
  std::vector<std::array<int, 3>> soup;
  for (int j = 0; j < n; ++j)
    for (int i = 0; i < n; ++i) {
      const int a = id(i, j), b = id(i + 1, j), c = id(i + 1, j + 1), d = id(i, j + 1);
      if (i >= flip_from)
        soup.insert(soup.end(), {{a, c, b}, {a, d, c}});
      else
        soup.insert(soup.end(), {{a, b, c}, {a, c, d}});
    }
  for (int k = 0; k < copies; ++k) {
    const std::array<int, 3> t = soup[static_cast<std::size_t>(50 * k)];
    soup.push_back({t[1], t[2], t[0]});
  }
  for (int k = 0; k < repeated; ++k) soup.push_back({id(k, 0), id(k, 0), id(k, 1)});
  std::mt19937 rng(3);
  std::shuffle(soup.begin(), soup.end(), rng);
  std::vector<double> xyz;
  std::vector<int> triangles;
  for (const auto& t : soup)
    for (const int v : t) {
      triangles.push_back(static_cast<int>(xyz.size() / 3));
      xyz.insert(xyz.end(), {static_cast<double>(v % (n + 1)), static_cast<double>(v / (n + 1)),
                             triangles.size() % 2 ? -0.0 : 0.0});
    }
  std::vector<LoadedMesh> read;
  for (const int threads : {1, 2}) {
    const ThreadLimit limit(threads);
    read.push_back(repair_triangles("soup", xyz, triangles, "soup", {}));
  }
  const MeshReport& r = read[0].report;
  EXPECT_EQ(r.input_faces, 2 * n * n + copies + repeated);
  EXPECT_EQ(r.welded_vertices, 3 * r.input_faces - (n + 1) * (n + 1));
  EXPECT_EQ(r.degenerate_faces, repeated);
  EXPECT_EQ(r.duplicate_faces, copies);
  EXPECT_EQ(r.unused_vertices, 0);
  EXPECT_EQ(r.flipped_faces, 2 * n * (n - flip_from));
  EXPECT_EQ(r.components, 1);
  EXPECT_EQ(r.boundary_edges, 4 * n);
  EXPECT_EQ(r.non_manifold_edges, 0);
  EXPECT_TRUE(r.orientable);
  EXPECT_DOUBLE_EQ(min_normal_z(read[0].mesh), 1.0);
  const MeshReport& r2 = read[1].report;
  EXPECT_EQ(std::tie(r.input_vertices, r.welded_vertices, r.degenerate_faces, r.duplicate_faces, r.flipped_faces,
                     r.components, r.boundary_edges),
            std::tie(r2.input_vertices, r2.welded_vertices, r2.degenerate_faces, r2.duplicate_faces,
                     r2.flipped_faces, r2.components, r2.boundary_edges));
  EXPECT_EQ(read[0].mesh.V, read[1].mesh.V);
  EXPECT_EQ(read[0].mesh.F, read[1].mesh.F);
}

// The weld keeps each point's first occurrence, in the file's order, also where distinct
// points share a weld hash (two found by a birthday search). In the soup the pair's copies
// alternate through the triangles, and one more point comes as +0 and as −0: the mesh's
// vertices are the points in order of first appearance, each face keeps its corners'
// coordinates, at one thread and at two.
TEST_F(ReadMesh, WeldKeepsFirstOccurrencesWhereHashesCollide) {
  using Point = std::array<double, 3>;
  std::mt19937_64 rng(5);
  const auto random_point = [&] {
    return Point{static_cast<double>(rng() % 100000), static_cast<double>(rng() % 100000),
                 static_cast<double>(rng() % 100000)};
  };
  std::unordered_map<std::uint32_t, Point> seen;
  Point a{}, b{};
  for (bool found = false; !found;) {
    const Point p = random_point();
    const auto [it, fresh] = seen.emplace(weld_hash(p.data()), p);
    if (!fresh && it->second != p) a = it->second, b = p, found = true;
  }
  ASSERT_EQ(weld_hash(a.data()), weld_hash(b.data()));
  std::vector<Point> corners;
  for (int i = 0; i < 40; ++i) {
    const Point c = random_point(), d = random_point();
    if (i % 2) corners.insert(corners.end(), {a, c, b});
    else corners.insert(corners.end(), {b, d, a});
    if (i % 7 == 0) corners.insert(corners.end(), {c, {0.0, 1.0, i % 3 ? 0.0 : -0.0}, d});
  }
  std::vector<double> xyz;
  std::vector<int> triangles;
  std::map<Point, int> first;  // −0 and +0 compare equal: one key
  std::vector<Point> want;     // the points in order of first appearance
  for (const Point& p : corners) {
    triangles.push_back(static_cast<int>(triangles.size()));
    xyz.insert(xyz.end(), p.begin(), p.end());
    if (first.emplace(p, static_cast<int>(want.size())).second) want.push_back(p);
  }
  for (const int threads : {1, 2}) {
    const ThreadLimit limit(threads);
    const LoadedMesh m = repair_triangles("soup", xyz, triangles, "soup", {});
    EXPECT_EQ(m.report.welded_vertices, static_cast<int>(corners.size() - want.size()));
    ASSERT_EQ(m.mesh.vertex_count(), static_cast<int>(want.size()));
    for (int v = 0; v < m.mesh.vertex_count(); ++v)
      for (std::size_t k = 0; k < 3; ++k)
        EXPECT_EQ(m.mesh.V(v, static_cast<int>(k)), want[static_cast<std::size_t>(v)][k]) << v;
    ASSERT_EQ(m.mesh.face_count(), static_cast<int>(corners.size() / 3));
    for (int f = 0; f < m.mesh.face_count(); ++f) {  // the same corners, perhaps reoriented
      std::array<int, 3> got{}, expected{};
      for (int k = 0; k < 3; ++k) {
        const auto at = static_cast<std::size_t>(k);
        got[at] = m.mesh.F(f, k);
        expected[at] = first.at(corners[3 * static_cast<std::size_t>(f) + at]);
      }
      std::sort(got.begin(), got.end());
      std::sort(expected.begin(), expected.end());
      EXPECT_EQ(got, expected) << "face " << f;
    }
  }
}

// The weld sorts points by 22 bits of their hash under 2^18 points and by all 32 from there
// (where unequal points sharing 22 bits would be many): on both sides of that switch a soup
// of a grid's triangles, shuffled, welds to the grid's points in order of first appearance,
// at one thread and at two.
TEST_F(ReadMesh, WeldKeepsFirstOccurrencesOnBothSidesOfItsKeyWidth) {
  for (const int n : {150, 300}) {  // 135,000 and 540,000 points
    SCOPED_TRACE(n);
    std::vector<std::array<int, 3>> soup;
    const auto id = [&](int i, int j) { return j * (n + 1) + i; };
    for (int j = 0; j < n; ++j)
      for (int i = 0; i < n; ++i) {
        const int a = id(i, j), b = id(i + 1, j), c = id(i + 1, j + 1), d = id(i, j + 1);
        soup.insert(soup.end(), {{a, b, c}, {a, c, d}});
      }
    std::mt19937 rng(static_cast<unsigned>(n));
    std::shuffle(soup.begin(), soup.end(), rng);
    std::vector<double> xyz;
    std::vector<int> triangles;
    std::vector<int> first(static_cast<std::size_t>((n + 1) * (n + 1)), -1);
    std::vector<int> want;  // grid points in order of first appearance
    for (const auto& t : soup)
      for (const int v : t) {
        triangles.push_back(static_cast<int>(xyz.size() / 3));
        xyz.insert(xyz.end(), {0.25 * (v % (n + 1)), 0.5 * (v / (n + 1)), 0.0});
        if (first[static_cast<std::size_t>(v)] < 0) {
          first[static_cast<std::size_t>(v)] = static_cast<int>(want.size());
          want.push_back(v);
        }
      }
    ASSERT_EQ(xyz.size() / 3 < (std::size_t{1} << 18), n == 150);
    for (const int threads : {1, 2}) {
      const ThreadLimit limit(threads);
      const LoadedMesh m = repair_triangles("soup", xyz, triangles, "soup", {});
      ASSERT_EQ(m.mesh.vertex_count(), (n + 1) * (n + 1));
      EXPECT_EQ(m.report.welded_vertices, static_cast<int>(triangles.size()) - (n + 1) * (n + 1));
      int wrong = 0;
      for (int v = 0; v < m.mesh.vertex_count(); ++v) {
        const int g = want[static_cast<std::size_t>(v)];
        const bool here =
            m.mesh.V(v, 0) == 0.25 * (g % (n + 1)) && m.mesh.V(v, 1) == 0.5 * (g / (n + 1));
        wrong += here ? 0 : 1;
      }
      EXPECT_EQ(wrong, 0);
      ASSERT_EQ(m.mesh.face_count(), 2 * n * n);
      for (int f = 0; f < m.mesh.face_count(); ++f) {  // each face on its own corners, in order
        const auto& t = soup[static_cast<std::size_t>(f)];
        for (int k = 0; k < 3; ++k) {
          const int corner = t[static_cast<std::size_t>(k)];
          wrong += m.mesh.F(f, k) == first[static_cast<std::size_t>(corner)] ? 0 : 1;
        }
      }
      EXPECT_EQ(wrong, 0);
    }
  }
}

// A binary PLY of triangles, with other values in its rows and another element, is read row by
// row in place (the rows have fixed sizes); it must read exactly as its ASCII twin, which the
// general reader reads, for each value type. A quad, an index out of range, a negative index
// or a point that is not finite send it to the general reader, which reads the quad and names
// the problem.
struct PlyTwin {
  std::string ascii, binary;
};
PlyTwin ply_twin(int n, bool doubles, const char* count_type, const char* index_type,
                 const std::function<void(int face, std::vector<int>& corners)>& edit_face = {},
                 const std::function<void(int vertex, double& x)>& edit_x = {}) {
  const std::string coordinate = doubles ? "double" : "float";
  const auto header = [&](const char* format) {
    return "ply\nformat " + std::string(format) + " 1.0\nelement vertex " +
           std::to_string((n + 1) * (n + 1)) + "\nproperty " + coordinate +
           " x\nproperty uchar red\nproperty " + coordinate + " y\nproperty float nx\nproperty " +
           coordinate + " z\nelement material 2\nproperty int id\nelement face " +
           std::to_string(2 * n * n) + "\nproperty uchar flags\nproperty list " + count_type + " " +
           index_type + " vertex_indices\nproperty float quality\nend_header\n";
  };
  PlyTwin twin{header("ascii"), header("binary_little_endian")};
  const auto text = [](double x) {
    char buffer[64];
    return std::string(buffer, std::to_chars(buffer, buffer + sizeof buffer, x).ptr);
  };
  const auto put_integer = [](std::string& s, const char* type, long long v) {
    const std::string t = type;
    const int bytes = t == "uchar" ? 1 : t == "ushort" ? 2 : 4;
    const auto bits = static_cast<unsigned long long>(v);
    for (int k = 0; k < bytes; ++k) s.push_back(static_cast<char>((bits >> (8 * k)) & 0xff));
  };
  std::mt19937 rng(7);
  for (int v = 0; v < (n + 1) * (n + 1); ++v) {
    double p[3] = {v % (n + 1) + 0.25 * static_cast<float>(rng() % 1000) / 1000.0,
                   static_cast<double>(v / (n + 1)), static_cast<float>(std::sin(0.1 * v))};
    if (!doubles)
      for (double& x : p) x = static_cast<float>(x);
    if (edit_x) edit_x(v, p[0]);
    twin.ascii += text(p[0]) + " 9 " + text(p[1]) + " 0.5 " + text(p[2]) + "\n";
    for (int k = 0; k < 3; ++k) {
      if (doubles) put_f64(twin.binary, p[k]);
      else put_f32(twin.binary, static_cast<float>(p[k]));
      if (k == 0) twin.binary.push_back(9);
      if (k == 1) put_f32(twin.binary, 0.5f);
    }
  }
  for (int id = 0; id < 2; ++id) {
    twin.ascii += std::to_string(id) + "\n";
    put_integer(twin.binary, "int", id);
  }
  for (int f = 0; f < 2 * n * n; ++f) {
    const int i = f / 2 % n, j = f / 2 / n;
    const int a = j * (n + 1) + i, b = a + 1, c = a + n + 2, d = a + n + 1;
    std::vector<int> corners = f % 2 ? std::vector<int>{a, c, d} : std::vector<int>{a, b, c};
    if (edit_face) edit_face(f, corners);
    twin.ascii += "1 " + std::to_string(corners.size());
    twin.binary.push_back(1);
    put_integer(twin.binary, count_type, static_cast<long long>(corners.size()));
    for (const int v : corners) {
      twin.ascii += " " + std::to_string(v);
      put_integer(twin.binary, index_type, v);
    }
    twin.ascii += " 0.75\n";
    put_f32(twin.binary, 0.75f);
  }
  return twin;
}

TEST_F(ReadMesh, BinaryTrianglePlyReadsAsItsAsciiTwin) {
  const auto same = [](const LoadedMesh& x, const LoadedMesh& y) {
    EXPECT_EQ(x.mesh.V, y.mesh.V);
    EXPECT_EQ(x.mesh.F, y.mesh.F);
    EXPECT_EQ(std::tie(x.report.input_vertices, x.report.input_faces, x.report.welded_vertices),
              std::tie(y.report.input_vertices, y.report.input_faces, y.report.welded_vertices));
  };
  for (const bool doubles : {false, true})
    for (const auto& [count_type, index_type] :
         {std::pair{"uchar", "int"}, std::pair{"int", "uint"}, std::pair{"uchar", "ushort"}})
      for (const int threads : {1, 2}) {
        SCOPED_TRACE(std::string(doubles ? "double" : "float") + " " + count_type + " " +
                     index_type + " at " + std::to_string(threads) + " threads");
        const ThreadLimit limit(threads);
        // 14.6k points and 28.8k faces: several pieces of rows.
        const PlyTwin twin = ply_twin(120, doubles, count_type, index_type);
        const LoadedMesh binary = read_mesh_bytes("twin.ply", twin.binary);
        EXPECT_EQ(binary.report.format, "ply-binary");
        EXPECT_EQ(binary.mesh.face_count(), 2 * 120 * 120);
        same(binary, read_mesh_bytes("twin.ply", twin.ascii));
      }

  // A quad among the triangles: the general reader splits it, as in the ASCII file.
  const PlyTwin quad = ply_twin(20, false, "uchar", "int", [](int f, std::vector<int>& corners) {
    if (f == 101) corners.push_back(corners[0] + 1), std::swap(corners[1], corners[3]);
  });
  const LoadedMesh with_quad = read_mesh_bytes("quad.ply", quad.binary);
  EXPECT_EQ(with_quad.report.input_faces, 2 * 20 * 20 + 1);
  same(with_quad, read_mesh_bytes("quad.ply", quad.ascii));

  const auto message = [](const std::string& bytes) {
    try {
      read_mesh_bytes("bad.ply", bytes);
    } catch (const Error& e) {
      return std::string(e.what());
    }
    return std::string("no error");
  };
  const int points = 21 * 21;
  EXPECT_EQ(message(ply_twin(20, false, "uchar", "int", [&](int f, std::vector<int>& corners) {
              if (f == 7) corners[1] = points;
            }).binary),
            "bad.ply: face 7 references vertex " + std::to_string(points) + " but the file has " +
                std::to_string(points) + " vertices");
  EXPECT_EQ(message(ply_twin(20, false, "uchar", "int", [](int f, std::vector<int>& corners) {
              if (f == 9) corners[2] = -1;
            }).binary),
            "bad.ply: face 9 references vertex -1");
  EXPECT_EQ(message(ply_twin(20, true, "uchar", "int", {}, [](int v, double& x) {
              if (v == 123) x = std::numeric_limits<double>::infinity();
            }).binary),
            "bad.ply: non-finite coordinate at vertex 123");
  EXPECT_EQ(message(ply_twin(20, true, "uchar", "int", {}, [](int v, double& x) {
              if (v == 5) x = 1e41;
            }).binary),
            "bad.ply: coordinate out of range (|x| > 1e40) at vertex 5");
}

// A part oriented consistently as read has its components counted in pieces of faces. A
// 200 × 100 grid of squares, shuffled, cut by removed columns into bands, an island cut out
// by a removed ring, and fins on interior edges (each a non-manifold edge: a fin is its
// band's); the count is a breadth-first search's over shared edges, at one thread and two,
// and the same with one face reversed (the orientation's own search counts it then). Not
// asked to count (as the solver reads), the read gives −1 and the same mesh and report.
TEST_F(ReadMesh, ComponentsAreCountedInPiecesWhenOrientedAsRead) {
  constexpr int nx = 200, ny = 100;
  const auto id = [](int i, int j) { return j * (nx + 1) + i; };
  const auto removed = [](int i, int j) {
    const bool cut_column = i % 50 == 25;
    const bool in_ring = i >= 60 && i <= 70 && j >= 40 && j <= 50;
    const bool ring = in_ring && (i == 60 || i == 70 || j == 40 || j == 50);
    return cut_column || ring;
  };
  std::vector<std::array<int, 3>> faces;
  for (int j = 0; j < ny; ++j)
    for (int i = 0; i < nx; ++i)
      if (!removed(i, j)) {
        faces.push_back({id(i, j), id(i + 1, j), id(i + 1, j + 1)});
        faces.push_back({id(i, j), id(i + 1, j + 1), id(i, j + 1)});
      }
  std::vector<double> xyz;
  for (int v = 0; v < (nx + 1) * (ny + 1); ++v)
    xyz.insert(xyz.end(),
               {static_cast<double>(v % (nx + 1)), static_cast<double>(v / (nx + 1)), 0.0});
  for (int k = 0; k < 20; ++k) {  // a fin up from an interior edge, on a vertex of its own
    const int i = 3 + 10 * k, j = 7 + 4 * k, fresh = static_cast<int>(xyz.size() / 3);
    xyz.insert(xyz.end(), {i + 0.5, j + 0.5, 1.0});
    faces.push_back({id(i, j), id(i + 1, j + 1), fresh});
  }
  std::mt19937 rng(9);
  std::shuffle(faces.begin(), faces.end(), rng);
  // The reference: faces joined across shared undirected edges, searched breadth first.
  std::map<std::pair<int, int>, std::vector<int>> by_edge;
  for (int f = 0; f < static_cast<int>(faces.size()); ++f)
    for (int k = 0; k < 3; ++k) {
      const int a = faces[static_cast<std::size_t>(f)][static_cast<std::size_t>(k)];
      const int b = faces[static_cast<std::size_t>(f)][static_cast<std::size_t>((k + 1) % 3)];
      by_edge[{std::min(a, b), std::max(a, b)}].push_back(f);
    }
  std::vector<std::vector<int>> next(faces.size());
  for (const auto& [edge, on] : by_edge)
    for (const int f : on)
      for (const int g : on)
        if (f != g) next[static_cast<std::size_t>(f)].push_back(g);
  std::vector<char> seen(faces.size(), 0);
  int want = 0;
  for (std::size_t seed = 0; seed < faces.size(); ++seed) {
    if (seen[seed]) continue;
    ++want;
    std::vector<int> queue = {static_cast<int>(seed)};
    seen[seed] = 1;
    while (!queue.empty()) {
      const int f = queue.back();
      queue.pop_back();
      for (const int g : next[static_cast<std::size_t>(f)])
        if (char& mark = seen[static_cast<std::size_t>(g)]; !mark) mark = 1, queue.push_back(g);
    }
  }
  EXPECT_EQ(want, 5 + 1);  // five bands and the island
  for (const bool reversed_one : {false, true}) {
    std::vector<int> triangles;
    for (const auto& t : faces) triangles.insert(triangles.end(), t.begin(), t.end());
    if (reversed_one) std::swap(triangles[4], triangles[5]);
    for (const int threads : {1, 2}) {
      SCOPED_TRACE(std::string(reversed_one ? "one face reversed" : "as read") + " at " +
                   std::to_string(threads) + " threads");
      const ThreadLimit limit(threads);
      const LoadedMesh m = repair_triangles("grid", xyz, triangles, "soup", {});
      EXPECT_EQ(m.report.components, want);
      EXPECT_EQ(m.report.non_manifold_edges, 20);
      EXPECT_EQ(m.report.flipped_faces, reversed_one ? 1 : 0);
      EXPECT_TRUE(m.report.orientable);
      ReadOptions uncounted;
      uncounted.count_components = false;
      const LoadedMesh u = repair_triangles("grid", xyz, triangles, "soup", uncounted);
      EXPECT_EQ(u.report.components, -1);
      EXPECT_TRUE(u.mesh.V == m.mesh.V && u.mesh.F == m.mesh.F);
      const MeshReport &got = u.report, &counted = m.report;
      EXPECT_EQ(
          std::tie(got.flipped_faces, got.boundary_edges, got.non_manifold_edges, got.orientable),
          std::tie(counted.flipped_faces, counted.boundary_edges, counted.non_manifold_edges,
                   counted.orientable));
    }
  }
}

TEST_F(ReadMesh, FlipReversesEverythingAfterRepair) {
  ReadOptions options;
  options.flip = true;
  const LoadedMesh m = read_mesh(write("grid.obj", grid_obj(8, 6)), options);
  EXPECT_EQ(m.report.flipped_faces, 32);
  EXPECT_DOUBLE_EQ(max_normal_z(m.mesh), -1.0);
  const LoadedMesh cube = read_mesh(kData + "/cube_quads.obj", options);
  EXPECT_NEAR(signed_volume(cube.mesh), -1.0, 1e-12);
}

TEST_F(ReadMesh, TopologyIsReported) {
  // A Möbius strip cannot be oriented; the reader says so and still returns it.
  const int n = 12;
  std::string s;
  for (int i = 0; i < n; ++i) {
    const double u = 2 * std::numbers::pi * i / n;
    for (double w : {-0.3, 0.3}) {
      const double r = 1 + w * std::cos(u / 2);
      s += "v " + std::to_string(r * std::cos(u)) + " " + std::to_string(r * std::sin(u)) + " " +
           std::to_string(w * std::sin(u / 2)) + "\n";
    }
  }
  for (int i = 0; i < n; ++i) {
    const int a = 2 * i + 1, b = 2 * i + 2;
    // After a full turn the strip comes back with its two sides exchanged.
    const int a1 = i + 1 < n ? a + 2 : 2, b1 = i + 1 < n ? b + 2 : 1;
    s += "f " + std::to_string(a) + " " + std::to_string(a1) + " " + std::to_string(b1) + " " +
         std::to_string(b) + "\n";
  }
  const LoadedMesh mobius = read_mesh(write("mobius.obj", s));
  EXPECT_FALSE(mobius.report.orientable);
  EXPECT_EQ(mobius.report.components, 1);
  EXPECT_EQ(mobius.mesh.face_count(), 2 * n);

  // Three triangles on one edge, plus a separate triangle.
  const LoadedMesh fan = read_mesh(write("fan.obj",
                                         "v 0 0 0\nv 1 0 0\nv 0 1 0\nv 0 -1 0\nv 0 0 1\n"
                                         "v 5 5 5\nv 6 5 5\nv 5 6 5\n"
                                         "f 1 2 3\nf 2 1 4\nf 1 2 5\nf 6 7 8\n"));
  EXPECT_EQ(fan.report.non_manifold_edges, 1);
  EXPECT_EQ(fan.report.components, 2);
  EXPECT_EQ(fan.report.boundary_edges, 6 + 3);
}

TEST_F(ReadMesh, BadInputThrowsOneLineNamingTheFile) {
  std::string truncated = cube_binary_stl(1000);
  expect_error("truncated.stl", truncated, "truncated");
  expect_error("short.stl", "solid\x01\x02", "truncated");
  expect_error("open_facet.stl", "solid x\nfacet normal 0 0 1\nouter loop\nvertex 0 0 0\n", "truncated");
  expect_error("header.ply", "ply\nformat ascii 1.0\nelement vertex 3\n", "truncated");
  std::string ply = cube_binary_ply();
  expect_error("body.ply", ply.substr(0, ply.size() - 5), "truncated");
  expect_error("ascii_body.ply",
               "ply\nformat ascii 1.0\nelement vertex 3\nproperty float x\nproperty float y\n"
               "property float z\nend_header\n0 0 0\n1 0\n",
               "truncated");

  expect_error("nan.obj", "v 0 0 0\nv nan 0 0\nv 0 1 0\nf 1 2 3\n", "non-finite");
  expect_error("overflow.obj", "v 0 0 0\nv 1e999 0 0\nv 0 1 0\nf 1 2 3\n", "non-finite");
  std::string inf = cube_binary_stl();
  inf.replace(84 + 12, 4, std::string("\x00\x00\x80\x7f", 4));  // +inf as float32
  expect_error("inf.stl", inf, "non-finite");
  expect_error("nan.ply",
               "ply\nformat ascii 1.0\nelement vertex 3\nproperty float x\nproperty float y\n"
               "property float z\nelement face 1\nproperty list uchar int vertex_indices\n"
               "end_header\n0 0 0\n1 0 inf\n0 1 0\n3 0 1 2\n",
               "non-finite");

  expect_error("range.obj", "v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 99\n", "references vertex 99");
  expect_error("relative.obj", "v 0 0 0\nv 1 0 0\nv 0 1 0\nf -1 -2 -4\n", "references vertex");
  expect_error("range.ply",
               "ply\nformat ascii 1.0\nelement vertex 3\nproperty float x\nproperty float y\n"
               "property float z\nelement face 1\nproperty list uchar int vertex_indices\n"
               "end_header\n0 0 0\n1 0 0\n0 1 0\n3 0 1 3\n",
               "references vertex 3");

  expect_error("points.obj", "v 0 0 0\nv 1 0 0\nv 0 1 0\n", "no triangles");
  expect_error("nofaces.ply",
               "ply\nformat ascii 1.0\nelement vertex 1\nproperty float x\nproperty float y\n"
               "property float z\nend_header\n0 0 0\n",
               "no triangles");
  expect_error("empty.stl", "", "empty");
  expect_error("comments.obj", "# nothing here\n", "empty");
  std::string zero = cube_binary_stl(0);
  expect_error("zero.stl", zero.substr(0, 84), "no triangles");

  expect_error("flat.obj", "v 0 0 0\nv 1 0 0\nv 2 0 0\nf 1 2 3\nf 3 2 1\n",
               "all 2 triangles are degenerate");
  expect_error("same.stl", "solid s\nfacet normal 0 0 0\nouter loop\nvertex 1 1 1\nvertex 1 1 1\n"
                           "vertex 1 1 1\nendloop\nendfacet\nendsolid s\n",
               "degenerate");

  expect_error("big.ply", "ply\nformat binary_big_endian 1.0\nelement vertex 0\nend_header\n",
               "unsupported");
  expect_error("notes.txt", "hello, this is not a mesh\n", "unsupported");
  expect_error("fake.ply", "solid x\n", "PLY");
  expect_error("bad.obj", "v 0 0 zero\n", "malformed");
  expect_error("bad.stl", "solid x\nfacet normal 0 0 1\nbanana\n", "unexpected");

  const std::string missing = (dir_ / "missing.stl").string();
  try {
    read_mesh(missing);
    ADD_FAILURE();
  } catch (const Error& e) {
    EXPECT_EQ(std::string(e.what()), missing + ": cannot open (No such file or directory)");
  }
  try {
    read_mesh(dir_.string());
    ADD_FAILURE();
  } catch (const Error& e) {
    EXPECT_NE(std::string(e.what()).find("cannot open"), std::string::npos);
  }
}

TEST_F(ReadMesh, EveryPrefixThrowsOrReads) {
  read_every_prefix("prefix.stl", cube_binary_stl());
  read_every_prefix("prefix.ply", cube_binary_ply());
  read_every_prefix("prefix_triangles.ply", ply_twin(3, false, "uchar", "int").binary);
  for (const char* name : {"cube_ascii.stl", "cube_quads.obj", "cube_ascii.ply"}) {
    std::ifstream in(kData + "/" + name, std::ios::binary);
    std::stringstream content;
    content << in.rdbuf();
    read_every_prefix(std::string("prefix_") + name, content.str());
  }
}

TEST_F(ReadMesh, GarbageNeverCrashes) {
  std::mt19937 rng(12345);
  std::uniform_int_distribution<int> byte(0, 255);
  const std::vector<std::string> valid = {cube_binary_stl(), cube_binary_ply()};
  for (int trial = 0; trial < 300; ++trial) {
    // Random bytes, then valid files with random bytes overwritten.
    std::string data(static_cast<std::size_t>(trial * 7 % 900), '\0');
    for (char& c : data) c = static_cast<char>(byte(rng));
    if (trial % 3 == 0) {
      data = valid[trial % 2];
      for (int k = 0; k < 4; ++k) data[rng() % data.size()] = static_cast<char>(byte(rng));
    }
    for (const char* ext : {".stl", ".ply", ".obj", ".bin"}) {
      const std::string path = write(std::to_string(trial) + "_garbage" + ext, data);
      try {
        read_mesh(path);
      } catch (const Error&) {
      }
      fs::remove(path);
    }
  }
}

TEST_F(ReadMesh, ShippedDataReadsCleanly) {
  const LoadedMesh blade = read_mesh(kData + "/../../data/propeller_blade_upper.stl");
  EXPECT_EQ(blade.report.format, "stl-ascii");
  EXPECT_EQ(blade.mesh.vertex_count(), 291);
  EXPECT_EQ(blade.mesh.face_count(), 522);
  EXPECT_EQ(blade.report.degenerate_faces, 0);
  EXPECT_EQ(blade.report.flipped_faces, 0);
  EXPECT_EQ(blade.report.non_manifold_edges, 0);
  EXPECT_EQ(blade.report.components, 1);
  EXPECT_TRUE(blade.report.orientable);
  EXPECT_GT(blade.report.boundary_edges, 0);  // an open face of the blade

  const LoadedMesh hypar = read_mesh(kData + "/../../data/hyperbolic_paraboloid.obj");
  EXPECT_EQ(hypar.report.format, "obj");
  EXPECT_EQ(hypar.mesh.vertex_count(), 81);
  EXPECT_EQ(hypar.mesh.face_count(), 128);
  EXPECT_EQ(hypar.report.welded_vertices, 0);
  EXPECT_EQ(hypar.report.flipped_faces, 0);
  EXPECT_EQ(hypar.report.boundary_edges, 32);
  EXPECT_EQ(hypar.report.components, 1);
  EXPECT_TRUE(hypar.report.orientable);
}

}  // namespace
}  // namespace flank::io
