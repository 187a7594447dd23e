// Mesh readers (STL ASCII/binary, OBJ, PLY ASCII/binary little-endian) and the validation and
// repair that turn a file into a Mesh the kernels may trust (kernels/mesh.h).
//
// Robustness rules: every byte offset is bounds-checked before it is read, every loop consumes
// input or is bounded by a count that was checked against the file size, and no arithmetic
// touches a coordinate before it is known to be finite (Debug test builds trap FP exceptions).
#include "io/read_mesh.h"

#include <algorithm>
#include <array>
#include <atomic>
#include <bit>
#include <charconv>
#include <cmath>
#include <cstdint>
#include <cstring>
#include <filesystem>
#include <limits>
#include <numeric>
#include <optional>
#include <span>
#include <string_view>
#include <utility>
#include <vector>

#include "io/encode.h"
#include "io/read_file.h"
#include "kernels/mesh.h"
#include "kernels/parallel.h"

namespace flank::io {
namespace {

// Coordinates beyond this cannot come from a real part and would let cross products overflow.
constexpr double kMaxCoordinate = 1e40;
// A face is degenerate when its area is at most this times the squared bbox diagonal.
constexpr double kDegenerateArea = 1e-14;

[[noreturn]] void fail(const std::string& path, const std::string& problem) {
  throw Error(path + ": " + problem);
}

bool equals_ci(std::string_view a, std::string_view b) {
  if (a.size() != b.size()) return false;
  for (std::size_t i = 0; i < a.size(); ++i) {
    char x = a[i], y = b[i];
    if (x >= 'A' && x <= 'Z') x = static_cast<char>(x - 'A' + 'a');
    if (y >= 'A' && y <= 'Z') y = static_cast<char>(y - 'A' + 'a');
    if (x != y) return false;
  }
  return true;
}

bool is_space(char c) {
  return c == ' ' || c == '\t' || c == '\r' || c == '\n' || c == '\f' || c == '\v';
}

// Splits off the next whitespace-separated token of `rest`; false when none is left.
bool next_token(std::string_view& rest, std::string_view& token) {
  std::size_t i = 0;
  while (i < rest.size() && is_space(rest[i])) ++i;
  if (i == rest.size()) {
    rest = {};
    return false;
  }
  std::size_t j = i;
  while (j < rest.size() && !is_space(rest[j])) ++j;
  token = rest.substr(i, j - i);
  rest.remove_prefix(j);
  return true;
}

// Iterates the lines of a text buffer (LF or CRLF), counting them from 1.
class Lines {
 public:
  explicit Lines(std::string_view data) : data_(data) {}
  bool next(std::string_view& line) {
    if (pos_ >= data_.size()) return false;
    const std::size_t end = data_.find('\n', pos_);
    const std::size_t stop = end == std::string_view::npos ? data_.size() : end;
    line = data_.substr(pos_, stop - pos_);
    if (!line.empty() && line.back() == '\r') line.remove_suffix(1);
    pos_ = stop + 1;
    ++number_;
    return true;
  }
  long long number() const { return number_; }
  // The line just returned is the last one and has no newline: the file may be cut short.
  bool cut_short() const { return pos_ > data_.size() && !data_.empty() && data_.back() != '\n'; }

 private:
  std::string_view data_;
  std::size_t pos_ = 0;
  long long number_ = 0;  // a 4 GiB file may hold more lines than an int counts
};

// Parses a whole token as a double. Overflow yields ±inf and underflow 0, so that the caller
// reports a non-finite coordinate instead of a syntax error. Never raises an FP exception.
bool parse_double(std::string_view token, double& value) {
  if (!token.empty() && token[0] == '+') token.remove_prefix(1);
  if (token.empty()) return false;
  const char* end = token.data() + token.size();
  const auto [ptr, ec] = std::from_chars(token.data(), end, value, std::chars_format::general);
  if (ptr != end) return false;
  if (ec == std::errc::result_out_of_range) {
    const bool negative_exponent = token.find("e-") != std::string_view::npos ||
                                   token.find("E-") != std::string_view::npos;
    const double inf = std::numeric_limits<double>::infinity();
    value = negative_exponent ? 0.0 : (token[0] == '-' ? -inf : inf);
    return true;
  }
  return ec == std::errc();
}

bool parse_integer(std::string_view token, long long& value) {
  if (!token.empty() && token[0] == '+') token.remove_prefix(1);
  if (token.empty()) return false;
  const char* end = token.data() + token.size();
  const auto [ptr, ec] = std::from_chars(token.data(), end, value);
  return ec == std::errc() && ptr == end;
}

std::uint32_t load_u32(const unsigned char* p) {
  return static_cast<std::uint32_t>(p[0]) | static_cast<std::uint32_t>(p[1]) << 8 |
         static_cast<std::uint32_t>(p[2]) << 16 | static_cast<std::uint32_t>(p[3]) << 24;
}

std::uint64_t load_u64(const unsigned char* p) {
  return static_cast<std::uint64_t>(load_u32(p)) | static_cast<std::uint64_t>(load_u32(p + 4)) << 32;
}

// Little-endian float32 widened to double. NaN and infinity are produced from constants rather
// than converted, because converting a signalling NaN raises FE_INVALID.
double load_f32(const unsigned char* p) {
  const std::uint32_t bits = load_u32(p);
  if (((bits >> 23) & 0xffu) == 0xffu) {
    if (bits & 0x7fffffu) return std::numeric_limits<double>::quiet_NaN();
    return (bits >> 31) ? -std::numeric_limits<double>::infinity()
                        : std::numeric_limits<double>::infinity();
  }
  float f;
  std::memcpy(&f, &bits, sizeof f);
  return static_cast<double>(f);
}

double load_f64(const unsigned char* p) {
  const std::uint64_t bits = load_u64(p);
  if (((bits >> 52) & 0x7ffu) == 0x7ffu) {  // even classifying a signalling NaN may trap
    if (bits & 0xfffffffffffffull) return std::numeric_limits<double>::quiet_NaN();
    return (bits >> 63) ? -std::numeric_limits<double>::infinity()
                        : std::numeric_limits<double>::infinity();
  }
  double d;
  std::memcpy(&d, &bits, sizeof d);
  return d;
}

// The file as read: vertex coordinates (3 per vertex) and triangles (3 indices per triangle),
// indices already checked to be in range, coordinates already checked to be finite.
struct RawMesh {
  std::vector<double> xyz;
  std::vector<int> triangles;
  // Set by a parser whose triangles use every point, each as it is read (binary STL): each
  // point's weld key (weld_key), and the points' box. repair then passes over them no more.
  Buffer<NarrowKeyedIndex> weld_keys;
  std::optional<std::array<Vec3, 2>> box;
};

// The weld sorts the points by the top bits of their hash, then by index: the copies of a
// point are adjacent, its first occurrence first. Where unequal points share those bits, their
// run is sorted by coordinates, then index. Under 2^18 points, 22 bits: two radix passes, which
// end in place (32 bits are three and a copy back), with few such runs (some n² / 2²³ pairs of
// n points). From 2^18 points the runs' sorts cost more than the pass saves: all 32 bits.
int weld_key_bits(std::size_t points) { return points < (std::size_t{1} << 18) ? 22 : 32; }

// Point p's weld key, its coordinates' −0 made +0 first (equal coordinates compare equal).
std::uint32_t weld_key(double* p, int bits) {
  for (int k = 0; k < 3; ++k) p[k] += 0.0;
  return weld_hash(p) >> (32 - bits);
}

// The reader's loops run in pieces of about kPiece items (at most 64 pieces), side by side on
// the command's threads; what a piece sums is combined in piece order, so results are the same
// whatever the thread count. Pieces of 16,384 left a real face's loops (24k-38k triangles) in
// one or two pieces, on one thread; at 2048 its read is 10-15% faster at two threads and 1-2%
// slower at one (forty-fourth part).
constexpr std::size_t kPiece = 2048;
std::size_t piece_count(std::size_t n) { return std::clamp<std::size_t>(n / kPiece, 1, 64); }

// Calls body(piece, begin, end) on each of `pieces` equal pieces of [0, n).
template <class Body>
void for_each_piece(std::size_t n, std::size_t pieces, const Body& body) {
  parallel_invoke_each(pieces,
                       [&](std::size_t c) { body(c, n * c / pieces, n * (c + 1) / pieces); });
}

// Finite and in range, or a one-line error naming the point: where(), called only then (every
// point read is checked; its name built each time was some 5% of a binary PLY's read).
template <class Where>
void check_coordinates(const std::string& path, const double* p, const Where& where) {
  for (int k = 0; k < 3; ++k) {
    if (!std::isfinite(p[k])) [[unlikely]]
      fail(path, "non-finite coordinate at " + where());
    if (std::abs(p[k]) > kMaxCoordinate) [[unlikely]]
      fail(path, "coordinate out of range (|x| > 1e40) at " + where());
  }
}

void check_vertex_count(const std::string& path, std::uint64_t vertices) {
  if (vertices > static_cast<std::uint64_t>(kMaxVertices))
    fail(path, "more than " + std::to_string(kMaxVertices) + " vertices (flank's limit)");
}

// `triangles` is exact when it was counted ahead (a binary PLY's face list), or the count so
// far when the file is refused as soon as it passes the limit.
void check_triangle_count(const std::string& path, std::uint64_t triangles, bool exact = false) {
  if (triangles <= static_cast<std::uint64_t>(kMaxTriangles)) return;
  fail(path, (exact ? std::to_string(triangles) + " triangles after splitting polygons, more"
                    : std::string("more")) +
                 " than flank's limit of " + std::to_string(kMaxTriangles) + " triangles");
}

// A polygon of `corners` vertices is fan-triangulated: at least 3, at most the limit.
void check_polygon(const std::string& path, const std::string& face, std::uint64_t corners,
                   const std::string& where = "") {
  if (corners < 3) fail(path, face + " has only " + std::to_string(corners) + " vertices" + where);
  if (corners > static_cast<std::uint64_t>(kMaxPolygonVertices))
    fail(path, face + " has " + std::to_string(corners) + " vertices (flank's limit is " +
                   std::to_string(kMaxPolygonVertices) + " per polygon)" + where);
}

// The same when the vertices are not all read yet: refused as soon as one is too many.
void check_polygon_growth(const std::string& path, const std::string& face, std::size_t corners,
                          const std::string& where) {
  if (corners > static_cast<std::size_t>(kMaxPolygonVertices))
    fail(path, face + " has more than " + std::to_string(kMaxPolygonVertices) +
                   " vertices (flank's limit per polygon)" + where);
}

// Appends the fan of `polygon` to `triangles`, three indices per triangle.
template <typename Index>
void fan_triangulate(const std::vector<Index>& polygon, std::vector<Index>& triangles) {
  for (std::size_t i = 1; i + 1 < polygon.size(); ++i)
    triangles.insert(triangles.end(), {polygon[0], polygon[i], polygon[i + 1]});
}

std::string_view skip_bom(std::string_view data) {
  if (data.size() >= 3 && static_cast<unsigned char>(data[0]) == 0xef &&
      static_cast<unsigned char>(data[1]) == 0xbb && static_cast<unsigned char>(data[2]) == 0xbf)
    data.remove_prefix(3);
  return data;
}

// ---------------------------------------------------------------------------------------- STL

bool starts_with_solid(std::string_view data) {
  data = skip_bom(data);
  std::string_view token;
  return next_token(data, token) && equals_ci(token, "solid");
}

// Text as ASCII STL or OBJ would be: no control bytes other than whitespace in the first
// kilobyte (a binary STL has its triangle count and first normal there; a corrupt byte further
// into an ASCII file is better reported by the ASCII parser).
bool looks_like_text(std::string_view data) {
  for (const char ch : data.substr(0, 1024)) {
    const unsigned char c = static_cast<unsigned char>(ch);
    if (c < 0x20 && !is_space(ch)) return false;
    if (c == 0x7f) return false;
  }
  return true;
}

bool binary_stl_size_matches(std::string_view data) {
  if (data.size() < 84) return false;
  const std::uint64_t n = load_u32(reinterpret_cast<const unsigned char*>(data.data()) + 80);
  return n > 0 && 84 + 50 * n == data.size();
}

RawMesh parse_stl_binary(const std::string& path, std::string_view data) {
  if (data.size() < 84)
    fail(path, "truncated binary STL (" + std::to_string(data.size()) +
                   " bytes, the header alone needs 84)");
  const auto* bytes = reinterpret_cast<const unsigned char*>(data.data());
  const std::uint64_t expected = load_u32(bytes + 80);
  const std::uint64_t holds = (data.size() - 84) / 50;
  if (expected > holds)
    fail(path, "truncated binary STL (expected " + std::to_string(expected) +
                   " triangles, file holds " + std::to_string(holds) + ")");
  // More records than the count means a garbled header or two files glued together: reading
  // only the count would drop part of the surface silently. A tail shorter than one record
  // holds no triangle and is tolerated (some exporters pad).
  if (holds > expected)
    fail(path, "binary STL header says " + std::to_string(expected) +
                   " triangles but the file holds " + std::to_string(holds) + " (" +
                   std::to_string(data.size()) + " bytes)");
  check_triangle_count(path, expected, true);
  // Records of a fixed size: read side by side; where any point fails its check, the records
  // are checked again in order, so that the message names the first. Every point is a corner
  // of its own: its weld key and the box are made here, while it is at hand (one pass over
  // the points fewer, and the weld's sort no longer beside the box: the faces' reads 2-5%
  // faster at one thread and 3-8% at two, the fifty-third part).
  RawMesh raw;
  raw.xyz.resize(9 * expected);
  raw.triangles.resize(3 * expected);
  const int bits = weld_key_bits(3 * expected);
  raw.weld_keys = Buffer<NarrowKeyedIndex>(3 * expected);
  const std::size_t pieces = piece_count(expected);
  std::vector<std::array<Vec3, 2>> boxes(pieces);  // each piece's, of its finite points
  std::atomic<bool> invalid{false};
  for_each_piece(expected, pieces, [&](std::size_t c, std::size_t begin, std::size_t end) {
    bool valid = true;
    Vec3 lo = Vec3::Constant(std::numeric_limits<double>::infinity()), hi = -lo;
    for (std::size_t t = begin; t < end; ++t) {
      const unsigned char* record = bytes + 84 + 50 * t + 12;  // skip the stored normal
      for (std::size_t corner = 3 * t; corner < 3 * t + 3; ++corner, record += 12) {
        double* p = raw.xyz.data() + 3 * corner;
        bool finite = true;
        for (int k = 0; k < 3; ++k) {
          p[k] = load_f32(record + 4 * k);
          if (!std::isfinite(p[k]) || std::abs(p[k]) > kMaxCoordinate) finite = false;
        }
        raw.weld_keys[corner] = {weld_key(p, bits), static_cast<std::int32_t>(corner)};
        raw.triangles[corner] = static_cast<int>(corner);
        if (!finite) {  // not compared: a NaN would raise FE_INVALID
          valid = false;
          continue;
        }
        const Vec3 q(p[0], p[1], p[2]);
        lo = lo.cwiseMin(q), hi = hi.cwiseMax(q);
      }
    }
    boxes[c] = {lo, hi};
    if (!valid) invalid.store(true, std::memory_order_relaxed);
  });
  if (invalid.load(std::memory_order_relaxed))
    for (std::uint64_t t = 0; t < expected; ++t)
      for (int corner = 0; corner < 3; ++corner)
        check_coordinates(path, &raw.xyz[9 * t + 3 * corner],
                          [&] { return "triangle " + std::to_string(t + 1); });
  raw.box = boxes[0];  // min and max are exact: the pieces' boxes make the same whatever the split
  for (const auto& [lo, hi] : boxes)
    (*raw.box)[0] = (*raw.box)[0].cwiseMin(lo), (*raw.box)[1] = (*raw.box)[1].cwiseMax(hi);
  return raw;
}

RawMesh parse_stl_ascii(const std::string& path, std::string_view data) {
  RawMesh raw;
  Lines lines(skip_bom(data));
  std::string_view line, token;
  bool in_loop = false;
  std::vector<int> loop;
  long long facet = 0;
  while (lines.next(line)) {
    if (!next_token(line, token)) continue;
    const std::string at_line = " at line " + std::to_string(lines.number());
    if (equals_ci(token, "vertex")) {
      if (!in_loop) fail(path, "vertex outside a facet loop" + at_line);
      double p[3];
      std::string_view number;
      for (int k = 0; k < 3; ++k)
        if (!next_token(line, number) || !parse_double(number, p[k]))
          fail(path, (lines.cut_short() ? "truncated ASCII STL (file ends in a vertex)"
                                        : "malformed vertex, expected 3 numbers") + at_line);
      check_coordinates(path, p, [&] { return "facet " + std::to_string(facet + 1) + at_line.substr(1); });
      check_vertex_count(path, raw.xyz.size() / 3 + 1);
      check_polygon_growth(path, "facet " + std::to_string(facet + 1), loop.size() + 1, at_line);
      loop.push_back(static_cast<int>(raw.xyz.size() / 3));
      raw.xyz.insert(raw.xyz.end(), p, p + 3);
    } else if (equals_ci(token, "outer")) {
      if (in_loop) fail(path, "nested 'outer loop'" + at_line);
      in_loop = true;
      loop.clear();
    } else if (equals_ci(token, "endloop")) {
      if (!in_loop) fail(path, "'endloop' without 'outer loop'" + at_line);
      check_polygon(path, "facet " + std::to_string(facet + 1), loop.size(), at_line);
      check_triangle_count(path, raw.triangles.size() / 3 + loop.size() - 2);
      fan_triangulate(loop, raw.triangles);
      in_loop = false;
      ++facet;
    } else if (equals_ci(token, "facet") || equals_ci(token, "endfacet") ||
               equals_ci(token, "solid") || equals_ci(token, "endsolid")) {
      if (in_loop) fail(path, "facet " + std::to_string(facet + 1) + " loop not closed" + at_line);
    } else {
      fail(path, "unexpected " + quote_text(token) + " in ASCII STL" + at_line);
    }
  }
  if (in_loop) fail(path, "truncated ASCII STL (facet " + std::to_string(facet + 1) + " not closed)");
  return raw;
}

// ---------------------------------------------------------------------------------------- OBJ

RawMesh parse_obj(const std::string& path, std::string_view data) {
  RawMesh raw;
  // Positive indices may point forward (many writers emit faces first), so the range is
  // checked at the end; remember which face each triangle came from for the message.
  std::vector<long long> indices;
  std::vector<long long> triangle_face;
  std::vector<long long> polygon;
  Lines lines(skip_bom(data));
  std::string_view line, token;
  long long face = 0;
  while (lines.next(line)) {
    const std::size_t hash = line.find('#');
    if (hash != std::string_view::npos) line = line.substr(0, hash);
    if (!next_token(line, token)) continue;
    const std::string at_line = " (line " + std::to_string(lines.number()) + ")";
    if (token == "v") {
      double p[3];
      std::string_view number;
      for (int k = 0; k < 3; ++k)
        if (!next_token(line, number) || !parse_double(number, p[k]))
          fail(path, (lines.cut_short() ? "truncated OBJ (file ends in a vertex)"
                                        : "malformed vertex, expected 3 numbers") + at_line);
      check_coordinates(path, p, [&] { return "vertex " + std::to_string(raw.xyz.size() / 3 + 1) + at_line; });
      check_vertex_count(path, raw.xyz.size() / 3 + 1);
      raw.xyz.insert(raw.xyz.end(), p, p + 3);
    } else if (token == "f") {
      ++face;
      polygon.clear();
      const long long preceding = static_cast<long long>(raw.xyz.size() / 3);
      std::string_view corner;
      while (next_token(line, corner)) {
        if (polygon.size() == static_cast<std::size_t>(kMaxPolygonVertices)) {
          // One line may be the whole file: count the rest rather than store it.
          std::uint64_t corners = polygon.size() + 1;
          for (std::string_view more; next_token(line, more);) ++corners;
          check_polygon(path, "face " + std::to_string(face), corners, at_line);
        }
        long long index;
        if (!parse_integer(corner.substr(0, corner.find('/')), index))
          fail(path, "malformed face " + std::to_string(face) + ": " + quote_text(corner) + at_line);
        if (index == 0) fail(path, "face " + std::to_string(face) + " has vertex index 0" + at_line);
        if (index < 0) {
          if (index < -preceding)
            fail(path, "face " + std::to_string(face) + " references vertex " +
                           std::to_string(index) + " but only " + std::to_string(preceding) +
                           " vertices precede it" + at_line);
          polygon.push_back(preceding + index);
        } else {
          polygon.push_back(index - 1);
        }
      }
      check_polygon(path, "face " + std::to_string(face), polygon.size(), at_line);
      check_triangle_count(path, triangle_face.size() + polygon.size() - 2);
      fan_triangulate(polygon, indices);
      triangle_face.resize(indices.size() / 3, face);
    }
    // Everything else (vt, vn, g, o, s, usemtl, mtllib, l, p, ...) does not shape Φ.
  }
  const long long vertices = static_cast<long long>(raw.xyz.size() / 3);
  raw.triangles.resize(indices.size());
  for (std::size_t i = 0; i < indices.size(); ++i) {
    if (indices[i] >= vertices)
      fail(path, "face " + std::to_string(triangle_face[i / 3]) + " references vertex " +
                     std::to_string(indices[i] + 1) + " but the file has " +
                     std::to_string(vertices) + " vertices");
    raw.triangles[i] = static_cast<int>(indices[i]);
  }
  return raw;
}

// ---------------------------------------------------------------------------------------- PLY

enum class PlyType { i8, u8, i16, u16, i32, u32, f32, f64 };

bool parse_ply_type(std::string_view name, PlyType& type) {
  static const std::pair<std::string_view, PlyType> kNames[] = {
      {"char", PlyType::i8},    {"int8", PlyType::i8},     {"uchar", PlyType::u8},
      {"uint8", PlyType::u8},   {"short", PlyType::i16},   {"int16", PlyType::i16},
      {"ushort", PlyType::u16}, {"uint16", PlyType::u16},  {"int", PlyType::i32},
      {"int32", PlyType::i32},  {"uint", PlyType::u32},    {"uint32", PlyType::u32},
      {"float", PlyType::f32},  {"float32", PlyType::f32}, {"double", PlyType::f64},
      {"float64", PlyType::f64}};
  for (const auto& [text, t] : kNames)
    if (name == text) {
      type = t;
      return true;
    }
  return false;
}

std::size_t ply_type_size(PlyType type) {
  switch (type) {
    case PlyType::i8:
    case PlyType::u8: return 1;
    case PlyType::i16:
    case PlyType::u16: return 2;
    case PlyType::i32:
    case PlyType::u32:
    case PlyType::f32: return 4;
    case PlyType::f64: return 8;
  }
  return 1;
}

bool ply_type_is_integer(PlyType type) { return type != PlyType::f32 && type != PlyType::f64; }

// A binary little-endian value as a double.
double load_ply_value(PlyType type, const unsigned char* p) {
  switch (type) {
    case PlyType::i8: return static_cast<std::int8_t>(p[0]);
    case PlyType::u8: return p[0];
    case PlyType::i16: return static_cast<std::int16_t>(p[0] | p[1] << 8);
    case PlyType::u16: return static_cast<std::uint16_t>(p[0] | p[1] << 8);
    case PlyType::i32: return static_cast<std::int32_t>(load_u32(p));
    case PlyType::u32: return load_u32(p);
    case PlyType::f32: return load_f32(p);
    case PlyType::f64: return load_f64(p);
  }
  return 0;
}

struct PlyProperty {
  std::string name;
  bool is_list = false;
  PlyType count_type = PlyType::u8;
  PlyType type = PlyType::f32;
};

struct PlyElement {
  std::string name;
  long long count = 0;
  std::vector<PlyProperty> properties;
};

enum class ReadStatus { ok, end, malformed };

// Values of the PLY body, one at a time, as doubles (every PLY integer type is exact in a
// double, so indices lose nothing).
class PlyBody {
 public:
  PlyBody(std::string_view body, bool binary) : body_(body), binary_(binary) {}

  ReadStatus read(PlyType type, double& value) {
    if (!binary_) {
      std::string_view token;
      if (!next_token(body_, token)) return ReadStatus::end;
      return parse_double(token, value) ? ReadStatus::ok : ReadStatus::malformed;
    }
    const std::size_t size = ply_type_size(type);
    if (body_.size() - pos_ < size) return ReadStatus::end;
    value = load_ply_value(type, reinterpret_cast<const unsigned char*>(body_.data()) + pos_);
    pos_ += size;
    return ReadStatus::ok;
  }

  std::size_t remaining_bytes() const { return body_.size() - pos_; }
  bool binary() const { return binary_; }

  // Binary only: passes over `bytes`; false if fewer remain.
  bool skip(std::uint64_t bytes) {
    if (bytes > remaining_bytes()) return false;
    pos_ += static_cast<std::size_t>(bytes);
    return true;
  }

 private:
  std::string_view body_;
  bool binary_;
  std::size_t pos_ = 0;
};

// A count or index value: finite, integral and within [lo, hi].
bool integral_in(double v, double lo, double hi) {
  return std::isfinite(v) && v >= lo && v <= hi && v == std::floor(v);
}

// Counts are claims: before anything is reserved, each element's rows must fit in the body
// (a binary row takes at least its fixed-size fields, an ASCII value a byte and a separator),
// the vertices must be within the limit, and a binary face list must not make more triangles
// than the limit (issue 14: 20 MB of 255-gons made 20.7 M triangles).
void check_ply_counts(const std::string& path, const std::vector<PlyElement>& elements,
                      const PlyElement* vertex_element, const PlyElement* face_element,
                      int index_property, PlyBody body) {
  const bool binary = body.binary();
  std::uint64_t ascii_bytes = body.remaining_bytes() + 1;  // the last value needs no separator
  for (const PlyElement& element : elements) {
    std::uint64_t min_row = 0;
    bool has_list = false;
    for (const PlyProperty& property : element.properties) {
      min_row += binary ? ply_type_size(property.is_list ? property.count_type : property.type) : 2;
      has_list = has_list || property.is_list;
    }
    if (min_row == 0) continue;  // rows without properties occupy no bytes
    const std::uint64_t fits = (binary ? body.remaining_bytes() : ascii_bytes) / min_row;
    if (static_cast<std::uint64_t>(element.count) > fits)
      fail(path, std::string("truncated ") + (binary ? "binary " : "") + "PLY (expected " +
                     std::to_string(element.count) + " " + element.name +
                     " rows, file holds at most " + std::to_string(fits) + ")");
    if (&element == vertex_element) check_vertex_count(path, element.count);
    if (&element == face_element) check_triangle_count(path, element.count);
    if (!binary) {  // ASCII rows are counted while read
      ascii_bytes -= static_cast<std::uint64_t>(element.count) * min_row;
      continue;
    }
    if (!has_list) {
      body.skip(static_cast<std::uint64_t>(element.count) * min_row);  // fits, checked above
      continue;
    }
    std::uint64_t triangles = 0;
    bool complete = true;
    for (long long r = 0; r < element.count && complete; ++r)
      for (std::size_t q = 0; q < element.properties.size() && complete; ++q) {
        const PlyProperty& property = element.properties[q];
        if (!property.is_list) {
          complete = body.skip(ply_type_size(property.type));
          continue;
        }
        double count = 0;
        complete = body.read(property.count_type, count) == ReadStatus::ok && count >= 0;
        if (!complete) break;
        if (&element == face_element && static_cast<int>(q) == index_property) {
          if (count > static_cast<double>(kMaxPolygonVertices))
            check_polygon(path, "face " + std::to_string(r), static_cast<std::uint64_t>(count));
          if (count >= 3) triangles += static_cast<std::uint64_t>(count) - 2;
        }
        complete = body.skip(static_cast<std::uint64_t>(count) * ply_type_size(property.type));
      }
    // A truncated list is reported by the reading pass, after this check of what it holds.
    check_triangle_count(path, triangles, true);
    if (!complete) return;
  }
}

// A binary PLY of triangles whose rows have fixed sizes: every element's properties are
// values, but for the face element's index list, and every face has three corners (what flank
// and most tools write). Its rows lie at known offsets and are read side by side. Anything
// else, or anything amiss (fewer bytes than the rows need, a polygon, an index out of range, a
// point not finite or out of range, a count over flank's limits), gives nothing: the general
// reader then reads the file and names the problem.
std::optional<RawMesh> parse_ply_triangles(std::string_view body,
                                           const std::vector<PlyElement>& elements,
                                           const PlyElement* vertex_element,
                                           const PlyElement* face_element,
                                           const int xyz_property[3], int index_property) {
  if (!face_element || face_element->count == 0) return std::nullopt;
  if (vertex_element->count > kMaxVertices || face_element->count > kMaxTriangles)
    return std::nullopt;
  // Each element's row size and first row; for the vertex element, where x, y and z lie in a
  // row, for the face element where the count and the indices do.
  std::uint64_t offset = 0, vertex_start = 0, vertex_row = 0, face_start = 0, face_row = 0;
  std::uint64_t xyz_at[3] = {0, 0, 0}, count_at = 0;
  for (const PlyElement& element : elements) {
    std::uint64_t row = 0;
    for (std::size_t q = 0; q < element.properties.size(); ++q) {
      const PlyProperty& property = element.properties[q];
      if (&element == vertex_element)
        for (int k = 0; k < 3; ++k)
          if (xyz_property[k] == static_cast<int>(q)) xyz_at[k] = row;
      if (!property.is_list) {
        row += ply_type_size(property.type);
        continue;
      }
      if (&element != face_element || static_cast<int>(q) != index_property ||
          !ply_type_is_integer(property.type))
        return std::nullopt;
      count_at = row;
      row += ply_type_size(property.count_type) + 3 * ply_type_size(property.type);
    }
    if (&element == vertex_element) vertex_start = offset, vertex_row = row;
    if (&element == face_element) face_start = offset, face_row = row;
    if (row > 0 && static_cast<std::uint64_t>(element.count) > (body.size() - offset) / row)
      return std::nullopt;
    offset += row * static_cast<std::uint64_t>(element.count);
  }
  const PlyProperty& list = face_element->properties[static_cast<std::size_t>(index_property)];
  const std::uint64_t index_size = ply_type_size(list.type);
  const std::uint64_t indices_at = count_at + ply_type_size(list.count_type);
  const auto* bytes = reinterpret_cast<const unsigned char*>(body.data());
  const auto nv = static_cast<std::size_t>(vertex_element->count);
  const auto nf = static_cast<std::size_t>(face_element->count);
  RawMesh raw;
  raw.xyz.resize(3 * nv);
  raw.triangles.resize(3 * nf);
  std::atomic<bool> amiss{false};
  PlyType xyz_type[3];
  for (int k = 0; k < 3; ++k)
    xyz_type[k] = vertex_element->properties[static_cast<std::size_t>(xyz_property[k])].type;
  parallel_for(0, nv, [&](std::size_t begin, std::size_t end) {
    bool fine = true;
    for (std::size_t v = begin; v < end; ++v)
      for (int k = 0; k < 3; ++k) {
        const double x =
            load_ply_value(xyz_type[k], bytes + vertex_start + vertex_row * v + xyz_at[k]);
        raw.xyz[3 * v + static_cast<std::size_t>(k)] = x;
        if (!std::isfinite(x) || std::abs(x) > kMaxCoordinate) fine = false;
      }
    if (!fine) amiss.store(true, std::memory_order_relaxed);
  }, kPiece);
  parallel_for(0, nf, [&](std::size_t begin, std::size_t end) {
    bool fine = true;
    for (std::size_t f = begin; f < end; ++f) {
      const unsigned char* row = bytes + face_start + face_row * f;
      if (load_ply_value(list.count_type, row + count_at) != 3) fine = false;
      for (std::size_t k = 0; k < 3; ++k) {
        const double index = load_ply_value(list.type, row + indices_at + index_size * k);
        if (!(index >= 0 && index < static_cast<double>(nv))) fine = false;
        raw.triangles[3 * f + k] = fine ? static_cast<int>(index) : 0;
      }
    }
    if (!fine) amiss.store(true, std::memory_order_relaxed);
  }, kPiece);
  if (amiss.load(std::memory_order_relaxed)) return std::nullopt;
  return raw;
}

RawMesh parse_ply(const std::string& path, std::string_view data, std::string& format) {
  // Header.
  std::size_t pos = 0;
  std::vector<PlyElement> elements;
  enum class Encoding { none, ascii, binary_le } encoding = Encoding::none;
  bool ended = false;
  for (long long number = 1; pos < data.size(); ++number) {
    const std::size_t end = data.find('\n', pos);
    if (end == std::string_view::npos) break;
    std::string_view line = data.substr(pos, end - pos);
    pos = end + 1;
    if (!line.empty() && line.back() == '\r') line.remove_suffix(1);
    const std::string at_line = " at header line " + std::to_string(number);
    std::string_view keyword;
    if (!next_token(line, keyword)) continue;
    if (number == 1) {
      if (keyword != "ply") fail(path, "not a PLY file (missing 'ply' magic)");
      continue;
    }
    if (keyword == "end_header") {
      ended = true;
      break;
    }
    if (keyword == "comment" || keyword == "obj_info") continue;
    std::string_view a, b, c, d;
    if (keyword == "format") {
      if (!next_token(line, a)) fail(path, "malformed PLY format line" + at_line);
      if (a == "ascii") {
        encoding = Encoding::ascii;
      } else if (a == "binary_little_endian") {
        encoding = Encoding::binary_le;
      } else if (a == "binary_big_endian") {
        fail(path, "binary_big_endian PLY is unsupported (convert it to binary_little_endian "
                   "or ascii)");
      } else {
        fail(path, "unsupported PLY format " + quote_text(a) + at_line);
      }
    } else if (keyword == "element") {
      long long count;
      if (!next_token(line, a) || !next_token(line, b) || !parse_integer(b, count) || count < 0)
        fail(path, "malformed PLY element line" + at_line);
      // The name goes into messages ("truncated PLY (expected 3 vertex rows ..."): printable
      // only, so that a file's bytes never reach the terminal (found by fuzz_ply).
      if (quote_text(a, a.size()) != "'" + std::string(a) + "'")
        fail(path, "malformed PLY element name " + quote_text(a) + at_line);
      elements.push_back({std::string(a), count, {}});
    } else if (keyword == "property") {
      if (elements.empty()) fail(path, "PLY property before any element" + at_line);
      PlyProperty property;
      if (!next_token(line, a)) fail(path, "malformed PLY property line" + at_line);
      if (a == "list") {
        property.is_list = true;
        if (!next_token(line, b) || !next_token(line, c) || !next_token(line, d) ||
            !parse_ply_type(b, property.count_type) || !parse_ply_type(c, property.type) ||
            !ply_type_is_integer(property.count_type))
          fail(path, "malformed PLY list property" + at_line);
        property.name = std::string(d);
      } else {
        if (!parse_ply_type(a, property.type) || !next_token(line, b))
          fail(path, "malformed PLY property " + quote_text(a) + at_line);
        property.name = std::string(b);
      }
      elements.back().properties.push_back(std::move(property));
    } else {
      fail(path, "unexpected " + quote_text(keyword) + " in PLY header" + at_line);
    }
  }
  if (!ended) fail(path, "truncated PLY header (no end_header)");
  if (encoding == Encoding::none) fail(path, "PLY header has no format line");
  const bool binary = encoding == Encoding::binary_le;
  format = binary ? "ply-binary" : "ply-ascii";

  // Where x, y, z and the face index list live.
  const PlyElement* vertex_element = nullptr;
  const PlyElement* face_element = nullptr;
  int xyz_property[3] = {-1, -1, -1};
  int index_property = -1;
  for (const PlyElement& element : elements) {
    if (element.name == "vertex" && !vertex_element) {
      vertex_element = &element;
      for (std::size_t p = 0; p < element.properties.size(); ++p)
        for (int k = 0; k < 3; ++k)
          if (!element.properties[p].is_list && element.properties[p].name == std::string(1, "xyz"[k]))
            xyz_property[k] = static_cast<int>(p);
      if (element.count > 0 && (xyz_property[0] < 0 || xyz_property[1] < 0 || xyz_property[2] < 0))
        fail(path, "PLY vertex element lacks an x, y or z property");
    } else if (element.name == "face" && !face_element) {
      face_element = &element;
      for (std::size_t p = 0; p < element.properties.size(); ++p)
        if (element.properties[p].is_list && (element.properties[p].name == "vertex_indices" ||
                                              element.properties[p].name == "vertex_index"))
          index_property = static_cast<int>(p);
      if (element.count > 0 && index_property < 0)
        fail(path, "PLY face element lacks a vertex_indices list");
    }
  }
  if (!vertex_element || vertex_element->count == 0) fail(path, "empty mesh (no vertices)");

  // Body.
  if (binary)
    if (std::optional<RawMesh> raw = parse_ply_triangles(
            data.substr(pos), elements, vertex_element, face_element, xyz_property, index_property))
      return std::move(*raw);
  PlyBody body(data.substr(pos), binary);
  check_ply_counts(path, elements, vertex_element, face_element, index_property, body);
  RawMesh raw;
  std::vector<long long> indices;
  std::vector<long long> triangle_face;
  std::vector<long long> polygon;
  for (const PlyElement& element : elements) {
    if (element.properties.empty()) continue;  // rows without properties occupy no bytes
    const bool is_vertex = &element == vertex_element;
    const bool is_face = &element == face_element;
    if (is_vertex) raw.xyz.reserve(3 * static_cast<std::size_t>(element.count));  // checked
    for (long long r = 0; r < element.count; ++r) {
      double p[3] = {0, 0, 0};
      for (std::size_t q = 0; q < element.properties.size(); ++q) {
        const PlyProperty& property = element.properties[q];
        const auto where = [&] {
          return std::string(" in ") + element.name + " " + std::to_string(r) + " of " +
                 std::to_string(element.count);
        };
        const auto read = [&](PlyType type, double& value) {
          const ReadStatus status = body.read(type, value);
          if (status == ReadStatus::end) fail(path, "truncated PLY (file ends" + where() + ")");
          if (status == ReadStatus::malformed) fail(path, "malformed PLY number" + where());
        };
        if (!property.is_list) {
          double value;
          read(property.type, value);
          if (is_vertex)
            for (int k = 0; k < 3; ++k)
              if (xyz_property[k] == static_cast<int>(q)) p[k] = value;
          continue;
        }
        double count;
        read(property.count_type, count);
        if (!integral_in(count, 0, 4294967295.0)) fail(path, "invalid PLY list length" + where());
        const bool indices_here = is_face && index_property == static_cast<int>(q);
        if (indices_here) {
          check_polygon(path, "face " + std::to_string(r), static_cast<std::uint64_t>(count));
          polygon.clear();
        }
        for (long long i = 0; i < static_cast<long long>(count); ++i) {
          double value;
          read(property.type, value);
          if (!indices_here) continue;
          if (!integral_in(value, -9e15, 9e15))
            fail(path, "invalid vertex index in face " + std::to_string(r));
          if (value < 0)
            fail(path, "face " + std::to_string(r) + " references vertex " +
                           std::to_string(static_cast<long long>(value)));
          polygon.push_back(static_cast<long long>(value));
        }
        if (indices_here) {
          check_triangle_count(path, triangle_face.size() + polygon.size() - 2);
          fan_triangulate(polygon, indices);
          triangle_face.resize(indices.size() / 3, r);
        }
      }
      if (is_vertex) {
        check_coordinates(path, p, [&] { return "vertex " + std::to_string(r); });
        raw.xyz.insert(raw.xyz.end(), p, p + 3);
      }
    }
  }
  const long long vertices = static_cast<long long>(raw.xyz.size() / 3);
  raw.triangles.resize(indices.size());
  for (std::size_t i = 0; i < indices.size(); ++i) {
    if (indices[i] >= vertices)
      fail(path, "face " + std::to_string(triangle_face[i / 3]) + " references vertex " +
                     std::to_string(indices[i]) + " but the file has " +
                     std::to_string(vertices) + " vertices");
    raw.triangles[i] = static_cast<int>(indices[i]);
  }
  return raw;
}

// ------------------------------------------------------------------------- validate and repair

// Three words' hash: each times an odd constant, summed, then mixed by MurmurHash3's 64-bit
// finalizer (a bijection that spreads every bit over the result).
std::uint64_t hash_words(std::uint64_t a, std::uint64_t b, std::uint64_t c) {
  std::uint64_t h =
      a * 0x9e3779b97f4a7c15ULL + b * 0xc2b2ae3d27d4eb4fULL + c * 0x165667b19e3779f9ULL;
  h ^= h >> 33;
  h *= 0xff51afd7ed558ccdULL;
  h ^= h >> 33;
  h *= 0xc4ceb9fe1a85ec53ULL;
  return h ^ (h >> 33);
}

// Calls run(first, last) on each run of equal keys in `sorted` (each run whole in one call,
// which may reorder it) and returns the sum of what the calls return. Pieces begin where runs
// do, found before any piece runs.
template <class Sum, class Item, class Run>
Sum sum_over_runs(Item* sorted, std::size_t n, const Run& run) {
  const std::size_t pieces = piece_count(n);
  std::vector<std::size_t> start(pieces + 1, n);
  for (std::size_t c = 0; c < pieces; ++c) {
    std::size_t i = n * c / pieces;
    while (i > 0 && i < n && sorted[i].key == sorted[i - 1].key) ++i;
    start[c] = i;
  }
  std::vector<Sum> sums(pieces, Sum{});
  parallel_invoke_each(pieces, [&](std::size_t c) {
    Sum sum{};  // summed here, stored once: pieces' sums share cache lines
    for (std::size_t i = start[c]; i < start[c + 1];) {
      std::size_t j = i + 1;
      while (j < start[c + 1] && sorted[j].key == sorted[i].key) ++j;
      sum += run(sorted + i, sorted + j);
      i = j;
    }
    sums[c] = std::move(sum);
  });
  Sum total{};
  for (const Sum& sum : sums) total += sum;
  return total;
}

// The edges' runs: how many are boundary edges (one face), and where each non-manifold edge's
// (three faces or more) begins in the sorted slots, in order.
struct EdgeRuns {
  int boundary = 0;
  std::vector<std::size_t> non_manifold;
  bool same = false;    // some manifold edge is run the same way by its two faces
  bool copies = false;  // two faces of some edge share their third vertex: the same corners
  EdgeRuns& operator+=(const EdgeRuns& o) {
    boundary += o.boundary;
    non_manifold.insert(non_manifold.end(), o.non_manifold.begin(), o.non_manifold.end());
    same = same || o.same;
    copies = copies || o.copies;
    return *this;
  }
};

struct UnionFind {
  Buffer<int> parent;
  explicit UnionFind(int n) : parent(static_cast<std::size_t>(n)) {
    std::iota(parent.begin(), parent.end(), 0);
  }
  // Every element on its own, set by the caller (parent[x] = x) before it is used: in pieces,
  // on their threads, where a serial start would write them all first.
  struct Unset {};
  UnionFind(int n, Unset) : parent(static_cast<std::size_t>(n)) {}
  int find(int x) {
    while (parent[x] != x) x = parent[x] = parent[parent[x]];
    return x;
  }
  void unite(int a, int b) {
    a = find(a), b = find(b);
    if (a != b) parent[std::max(a, b)] = std::min(a, b);
  }
};

// Removes every face on the same three vertices as an earlier face, in any order or
// orientation, keeping the first, and moves the faces kept to the front of `triangles`;
// returns how many went. Copies make decompose crawl and turn every edge non-manifold (issue
// 14 rows 8, 9): a part written twice reads as the part.
int drop_duplicate_faces(std::span<int> triangles) {
  const std::size_t nf = triangles.size() / 3;
  // Faces sorted by a 32-bit hash of their sorted vertices, then by index (as the points are).
  Buffer<std::array<int, 3>> vertices(nf);
  Buffer<NarrowKeyedIndex> order(nf);
  Buffer<char> duplicate(nf);
  parallel_for(0, nf, [&](std::size_t begin, std::size_t end) {
    std::fill(duplicate.data() + begin, duplicate.data() + end, 0);
    for (std::size_t f = begin; f < end; ++f) {
      // Sorted by minima and maxima, without branches: a comparison sort branches on the
      // vertices' order, which changes from face to face on some parts (this loop took
      // 0.41 ms on Rotor 67 upper's 38k faces with std::sort, 0.07 ms so).
      const int* t = triangles.data() + 3 * f;
      const int lo = std::min(t[0], t[1]), hi = std::max(t[0], t[1]);
      std::array<int, 3>& v = vertices[f];
      v = {std::min(lo, t[2]), std::max(lo, std::min(hi, t[2])), std::max(hi, t[2])};
      const std::uint64_t hash = hash_words(static_cast<std::uint32_t>(v[0]),
                                            static_cast<std::uint32_t>(v[1]),
                                            static_cast<std::uint32_t>(v[2]));
      order[f] = {static_cast<std::uint32_t>(hash >> 32), static_cast<std::int32_t>(f)};
    }
  }, kPiece);
  radix_sort_by_key(order, 32);
  const auto run = [&](NarrowKeyedIndex* first, NarrowKeyedIndex* last) {
    if (last - first == 1) return 0;
    std::sort(first, last, [&](const NarrowKeyedIndex& a, const NarrowKeyedIndex& b) {
      const std::array<int, 3>&x = vertices[a.index], &y = vertices[b.index];
      return x != y ? x < y : a.index < b.index;
    });
    int copies = 0;
    for (const NarrowKeyedIndex* k = first + 1; k < last; ++k)
      if (vertices[k->index] == vertices[(k - 1)->index]) duplicate[k->index] = 1, ++copies;
    return copies;
  };
  const int dropped = sum_over_runs<int>(order.data(), order.size(), run);
  if (dropped == 0) return 0;
  std::size_t out = 0;
  for (std::size_t f = 0; f < nf; ++f)
    if (!duplicate[f])
      for (int k = 0; k < 3; ++k) triangles[out++] = triangles[3 * f + k];
  return dropped;
}

// The edge-connected components of `nf` faces, oriented consistently: `link` holds, per edge
// slot, the face across a manifold edge (times two, plus one where both run it the same way)
// or −1, and `slots` the sorted slots whose non-manifold runs `edges` lists. A union-find in
// pieces of faces, side by side (links within a piece), then over the links between pieces
// and the non-manifold edges.
int linked_components(int nf, const Buffer<int>& link, const Buffer<KeyedIndex>& slots,
                      const EdgeRuns& edges) {
  UnionFind components(nf, UnionFind::Unset{});
  const std::size_t pieces = piece_count(static_cast<std::size_t>(nf));
  std::vector<std::vector<std::pair<int, int>>> across(pieces);  // face pairs, per piece
  std::vector<int> roots(pieces, 0);
  for_each_piece(static_cast<std::size_t>(nf), pieces, [&](std::size_t c, std::size_t begin,
                                                           std::size_t end) {
    std::vector<std::pair<int, int>> mine;  // moved in once: the lists' headers share lines
    std::iota(components.parent.begin() + begin, components.parent.begin() + end,
              static_cast<int>(begin));
    for (std::size_t f = begin; f < end; ++f)
      for (std::size_t k = 0; k < 3; ++k) {
        const int to = link[3 * f + k];
        const auto g = static_cast<std::size_t>(to / 2);
        if (to < 0 || g < f) continue;  // each pair once, from its lower face
        if (g < end)
          components.unite(static_cast<int>(f), static_cast<int>(g));  // roots stay in the piece
        else
          mine.emplace_back(static_cast<int>(f), static_cast<int>(g));
      }
    across[c] = std::move(mine);
  });
  for (const auto& pairs : across)
    for (const auto& [f, g] : pairs) components.unite(f, g);
  for (const std::size_t first : edges.non_manifold)
    for (std::size_t i = first + 1; i < slots.size() && slots[i].key == slots[first].key; ++i)
      components.unite(slots[first].index / 3, slots[i].index / 3);
  for_each_piece(static_cast<std::size_t>(nf), pieces, [&](std::size_t c, std::size_t begin,
                                                           std::size_t end) {
    int here = 0;  // counted here, stored once
    for (std::size_t f = begin; f < end; ++f)
      here += components.parent[f] == static_cast<int>(f) ? 1 : 0;
    roots[c] = here;
  });
  return std::accumulate(roots.begin(), roots.end(), 0);
}

// The edges' sorted slots into `slots`, per slot the face across a manifold edge into `link`
// (times two, plus one where both faces run the edge the same way; −1 elsewhere), and the
// runs' counts (see repair).
EdgeRuns link_edges(const Mesh& mesh, Buffer<KeyedIndex>& slots, Buffer<int>& link) {
  slots = sorted_edge_slots(mesh);
  link = Buffer<int>(slots.size());  // every slot is in one run, which sets its link
  // The slot's edge runs from the smaller to the larger index; the vertex off the slot's edge.
  const auto forward = [&](int slot) {
    const int f = slot / 3, k = slot % 3;
    return mesh.F(f, k) < mesh.F(f, (k + 1) % 3);
  };
  const auto third = [&](int slot) { return mesh.F(slot / 3, (slot % 3 + 2) % 3); };
  const auto edge_run = [&](const KeyedIndex* first, const KeyedIndex* last) {
    EdgeRuns runs;
    if (last - first != 2)
      for (const KeyedIndex* k = first; k < last; ++k)
        link[static_cast<std::size_t>(k->index)] = -1;
    if (last - first == 1) runs.boundary = 1;
    if (last - first > 2) {
      runs.non_manifold.push_back(static_cast<std::size_t>(first - slots.data()));
      std::vector<int> thirds;
      for (const KeyedIndex* k = first; k < last; ++k) thirds.push_back(third(k->index));
      std::ranges::sort(thirds);
      runs.copies = std::ranges::adjacent_find(thirds) != thirds.end();
    }
    if (last - first == 2) {
      const int a = first->index, b = (first + 1)->index;
      const int same = forward(a) == forward(b) ? 1 : 0;
      link[static_cast<std::size_t>(a)] = 2 * (b / 3) + same;
      link[static_cast<std::size_t>(b)] = 2 * (a / 3) + same;
      runs.same = same == 1;
      runs.copies = third(a) == third(b);
    }
    return runs;
  };
  return sum_over_runs<EdgeRuns>(slots.data(), slots.size(), edge_run);
}

LoadedMesh repair(const std::string& path, RawMesh raw, std::string format,
                  const ReadOptions& options) {
  LoadedMesh out;
  MeshReport& report = out.report;
  report.format = std::move(format);
  const int nv = static_cast<int>(raw.xyz.size() / 3);
  const int nt = static_cast<int>(raw.triangles.size() / 3);
  report.input_vertices = nv;
  report.input_faces = nt;
  if (nv == 0) fail(path, nt == 0 ? "empty mesh (no vertices, no triangles)" : "empty mesh (no vertices)");
  if (nt == 0) fail(path, "no triangles (" + std::to_string(nv) + " vertices, no faces)");

  // Weld exact duplicates onto the first occurrence, so a clean file keeps its numbering.
  const auto coord = [&](int v) { return raw.xyz.data() + 3 * static_cast<std::size_t>(v); };
  // Points sorted by their weld key (weld_key_bits), then by index.
  const int weld_bits = weld_key_bits(static_cast<std::size_t>(nv));
  Buffer<NarrowKeyedIndex> order = std::move(raw.weld_keys);
  if (order.empty()) {
    order = Buffer<NarrowKeyedIndex>(static_cast<std::size_t>(nv));
    parallel_for(0, static_cast<std::size_t>(nv), [&](std::size_t begin, std::size_t end) {
      for (std::size_t v = begin; v < end; ++v)
        order[v] = {weld_key(coord(static_cast<int>(v)), weld_bits), static_cast<std::int32_t>(v)};
    }, kPiece);
  }
  // The box of the points the triangles use, beside the sort (which runs on one thread under
  // 32,768 points); min and max are exact, so pieces' boxes make the same.
  const auto point = [&](int v) { return Vec3(coord(v)[0], coord(v)[1], coord(v)[2]); };
  Vec3 lo, hi;
  const auto find_box = [&] {
    const std::size_t corner_pieces = piece_count(raw.triangles.size());
    constexpr double kInfinity = std::numeric_limits<double>::infinity();
    std::vector<Vec3> piece_lo(corner_pieces, Vec3::Constant(kInfinity));
    std::vector<Vec3> piece_hi(corner_pieces, -piece_lo[0]);
    for_each_piece(raw.triangles.size(), corner_pieces, [&](std::size_t c, std::size_t begin,
                                                            std::size_t end) {
      Vec3 piece_min = piece_lo[c], piece_max = piece_hi[c];
      for (std::size_t i = begin; i < end; ++i) {
        const Vec3 p = point(raw.triangles[i]);
        piece_min = piece_min.cwiseMin(p), piece_max = piece_max.cwiseMax(p);
      }
      piece_lo[c] = piece_min, piece_hi[c] = piece_max;
    });
    lo = piece_lo[0], hi = piece_hi[0];
    for (std::size_t c = 1; c < corner_pieces; ++c)
      lo = lo.cwiseMin(piece_lo[c]), hi = hi.cwiseMax(piece_hi[c]);
  };
  if (raw.box) {
    lo = (*raw.box)[0], hi = (*raw.box)[1];
    radix_sort_by_key(order, weld_bits);
  } else {
    run_beside(find_box, [&] { radix_sort_by_key(order, weld_bits); });
  }
  Buffer<int> representative(static_cast<std::size_t>(nv));  // every point's set by its run
  const auto same_point = [&](int a, int b) {
    return std::equal(coord(a), coord(a) + 3, coord(b));
  };
  const auto run = [&](NarrowKeyedIndex* first, NarrowKeyedIndex* last) {
    const auto copy = [&](const NarrowKeyedIndex& k) { return same_point(k.index, first->index); };
    if (std::all_of(first + 1, last, copy)) {
      for (const NarrowKeyedIndex* k = first; k < last; ++k)
        representative[k->index] = first->index;
      return 1;
    }
    std::sort(first, last, [&](const NarrowKeyedIndex& a, const NarrowKeyedIndex& b) {
      const double *p = coord(a.index), *q = coord(b.index);
      return p[0] != q[0]   ? p[0] < q[0]
             : p[1] != q[1] ? p[1] < q[1]
             : p[2] != q[2] ? p[2] < q[2]
                            : a.index < b.index;
    });
    int points = 0;
    for (const NarrowKeyedIndex* k = first; k < last; ++k) {
      const bool same = k > first && same_point(k->index, (k - 1)->index);
      points += same ? 0 : 1;
      representative[k->index] = same ? representative[(k - 1)->index] : k->index;
    }
    return points;
  };
  const int unique = sum_over_runs<int>(order.data(), order.size(), run);
  report.welded_vertices = nv - unique;

  // Drop degenerate faces: repeated (welded) index or area ≤ 1e-14 · diagonal² (the box of
  // the points the triangles use: a binary STL's from its parse, another's found beside the
  // weld's sort above).
  const double area_floor = kDegenerateArea * (hi - lo).squaredNorm();
  const auto welded = [&](int t) {
    const int* corner = raw.triangles.data() + 3 * static_cast<std::size_t>(t);
    return std::array<int, 3>{representative[corner[0]], representative[corner[1]],
                              representative[corner[2]]};
  };
  // Each piece writes its kept faces' welded corners from where its first face's would go,
  // in order; where faces were dropped, the pieces' runs are then moved up to close the gaps
  // (most files drop none: one pass over the faces, not two).
  const std::size_t face_pieces = piece_count(static_cast<std::size_t>(nt));
  std::vector<int> kept_before(face_pieces + 1, 0);  // kept faces before piece c, once summed
  std::vector<std::size_t> piece_begin(face_pieces, 0);
  Buffer<int> kept(3 * static_cast<std::size_t>(nt));
  for_each_piece(static_cast<std::size_t>(nt), face_pieces, [&](std::size_t c, std::size_t begin,
                                                                std::size_t end) {
    int kept_here = 0;  // counted here, stored once: the pieces' counts share cache lines
    int* next = kept.data() + 3 * begin;
    for (std::size_t t = begin; t < end; ++t) {
      const auto [a, b, c3] = welded(static_cast<int>(t));
      bool bad = a == b || b == c3 || a == c3;
      if (!bad)
        bad = 0.5 * (point(b) - point(a)).cross(point(c3) - point(a)).norm() <= area_floor;
      if (bad) continue;
      next[0] = a, next[1] = b, next[2] = c3;
      next += 3;
      ++kept_here;
    }
    piece_begin[c] = begin;
    kept_before[c + 1] = kept_here;
  });
  std::partial_sum(kept_before.begin(), kept_before.end(), kept_before.begin());
  report.degenerate_faces = nt - kept_before.back();
  if (kept_before.back() == 0)
    fail(path, nt == 1 ? std::string("the only triangle is degenerate")
                       : "all " + std::to_string(nt) + " triangles are degenerate");
  if (report.degenerate_faces > 0)  // each run moves up, never past a later one's start
    for (std::size_t c = 1; c < face_pieces; ++c)
      std::memmove(kept.data() + 3 * static_cast<std::size_t>(kept_before[c]),
                   kept.data() + 3 * piece_begin[c],
                   3 * sizeof(int) * static_cast<std::size_t>(kept_before[c + 1] - kept_before[c]));
  // Faces on the same three vertices as an earlier one are dropped below, once the edges'
  // runs have shown there are some: they use the vertices their first copy uses.
  int nf = kept_before.back();

  // Remove unused vertices, keeping the file's order.
  std::vector<char> used(static_cast<std::size_t>(nv), 0);
  parallel_for(0, 3 * static_cast<std::size_t>(nf), [&](std::size_t begin, std::size_t end) {
    for (std::size_t i = begin; i < end; ++i)
      std::atomic_ref<char>(used[kept[i]]).store(1, std::memory_order_relaxed);
  }, 3 * kPiece);
  const std::size_t vertex_pieces = piece_count(static_cast<std::size_t>(nv));
  std::vector<int> used_before(vertex_pieces + 1, 0);
  for_each_piece(static_cast<std::size_t>(nv), vertex_pieces, [&](std::size_t c, std::size_t begin,
                                                                  std::size_t end) {
    used_before[c + 1] = static_cast<int>(std::count(used.data() + begin, used.data() + end, 1));
  });
  std::partial_sum(used_before.begin(), used_before.end(), used_before.begin());
  const int used_count = used_before.back();
  report.unused_vertices = unique - used_count;
  Mesh& mesh = out.mesh;
  mesh.V.resize(used_count, 3);
  Buffer<int> new_index(static_cast<std::size_t>(nv));  // read only where used: set there
  for_each_piece(static_cast<std::size_t>(nv), vertex_pieces, [&](std::size_t c, std::size_t begin,
                                                                  std::size_t end) {
    int next = used_before[c];
    for (std::size_t v = begin; v < end; ++v)
      if (used[v]) {
        new_index[v] = next;
        mesh.V.row(next++) = point(static_cast<int>(v)).transpose();
      }
  });
  mesh.F.resize(nf, 3);
  parallel_for(0, static_cast<std::size_t>(nf), [&](std::size_t begin, std::size_t end) {
    for (auto f = static_cast<Eigen::Index>(begin); f < static_cast<Eigen::Index>(end); ++f)
      for (int k = 0; k < 3; ++k)
        mesh.F(f, k) = new_index[kept[static_cast<std::size_t>(3 * f + k)]];
  }, kPiece);

  // Edges: the 3F edge slots sorted by undirected key, then by face; a run of equal keys is
  // one edge (a face has three different edges: it is not degenerate). A manifold edge (a run
  // of two) links its faces and carries the orientation constraint: `same` means both faces
  // run the edge in the same direction, i.e. one of them must be flipped. A face lists its
  // neighbours in the order of their edges' keys: the order the search below visits them in.
  Buffer<KeyedIndex> slots;
  // Per slot, the face across its edge times two, plus one where `same`; -1 where the edge is
  // not manifold.
  Buffer<int> link;
  EdgeRuns edges = link_edges(mesh, slots, link);
  if (edges.copies) {
    // A face on the same corners as another shares all three edges with it, and its third
    // vertex on each: the runs see every such pair. Rare, so found exactly, and the edges
    // found again, only then. Dropping copies keeps the vertices used.
    const std::span<int> corners(mesh.F.data(), 3 * static_cast<std::size_t>(nf));
    report.duplicate_faces = drop_duplicate_faces(corners);
    nf -= report.duplicate_faces;
    mesh.F.conservativeResize(nf, 3);  // row-major: the faces kept are the first rows
    edges = link_edges(mesh, slots, link);
  }
  report.boundary_edges = edges.boundary;
  report.non_manifold_edges = static_cast<int>(edges.non_manifold.size());
  // Faces that run every manifold edge they share in opposite directions (most parts as read)
  // are oriented consistently already: the search below would flip none of them.
  if (!edges.same) {
    report.components = options.count_components ? linked_components(nf, link, slots, edges) : -1;
    if (options.flip) mesh.F.col(1).swap(mesh.F.col(2));
    return out;
  }

  struct Neighbour {
    int face = -1;
    bool same = false;
  };
  std::vector<std::array<Neighbour, 3>> neighbours(nf);
  std::vector<unsigned char> neighbour_count(nf, 0);
  parallel_for(0, static_cast<std::size_t>(nf), [&](std::size_t begin, std::size_t end) {
    for (std::size_t f = begin; f < end; ++f) {
      std::array<std::pair<std::uint64_t, int>, 3> mine{};  // edge key, link
      int count = 0;
      for (int k = 0; k < 3; ++k)
        if (const int to = link[3 * f + static_cast<std::size_t>(k)]; to >= 0)
          mine[static_cast<std::size_t>(count++)] = {edge_key(mesh, static_cast<int>(f), k), to};
      for (int a = 1; a < count; ++a)  // by key: at most three
        for (auto b = static_cast<std::size_t>(a); b > 0 && mine[b].first < mine[b - 1].first; --b)
          std::swap(mine[b], mine[b - 1]);
      for (int k = 0; k < count; ++k) {
        const int to = mine[static_cast<std::size_t>(k)].second;
        neighbours[f][static_cast<std::size_t>(k)] = {to / 2, to % 2 == 1};
      }
      neighbour_count[f] = static_cast<unsigned char>(count);
    }
  }, kPiece);

  // Consistent orientation by BFS over manifold edges; per patch, keep the orientation that
  // the larger area had in the file (ties: the patch's first face keeps its orientation).
  const VecX area = face_areas(mesh);
  std::vector<signed char> flip(nf, -1);
  std::vector<int> patch(nf);
  std::vector<int> queue;
  int patches = 0;
  for (int seed = 0; seed < nf; ++seed) {
    if (flip[seed] >= 0) continue;
    queue.assign(1, seed);
    flip[seed] = 0;
    for (std::size_t head = 0; head < queue.size(); ++head) {
      const int f = queue[head];
      patch[f] = patches;
      for (int k = 0; k < neighbour_count[f]; ++k) {
        const int g = neighbours[f][k].face;
        const signed char want = static_cast<signed char>(flip[f] ^ (neighbours[f][k].same ? 1 : 0));
        if (flip[g] < 0) {
          flip[g] = want;
          queue.push_back(g);
        } else if (flip[g] != want) {
          report.orientable = false;
        }
      }
    }
    ++patches;
    double flipped_area = 0.0, kept_area = 0.0;
    for (int f : queue) (flip[f] ? flipped_area : kept_area) += area(f);
    if (flipped_area > kept_area)
      for (int f : queue) flip[f] ^= 1;
  }
  for (int f = 0; f < nf; ++f)
    if (flip[f]) {
      std::swap(mesh.F(f, 1), mesh.F(f, 2));
      ++report.flipped_faces;
    }
  // Components join across every shared edge: the patches (joined across manifold edges) are
  // joined across the non-manifold ones too.
  if (options.count_components) {
    UnionFind components(patches);
    for (const std::size_t first : edges.non_manifold)
      for (std::size_t i = first + 1; i < slots.size() && slots[i].key == slots[first].key; ++i)
        components.unite(patch[slots[first].index / 3], patch[slots[i].index / 3]);
    for (int p = 0; p < patches; ++p)
      if (components.find(p) == p) ++report.components;
  } else {
    report.components = -1;
  }
  if (options.flip) mesh.F.col(1).swap(mesh.F.col(2));
  return out;
}

bool has_obj_vertex_line(std::string_view data) {
  Lines lines(skip_bom(data));
  std::string_view line, token;
  while (lines.next(line))
    if (next_token(line, token) && token == "v") return true;
  return false;
}

}  // namespace

// The coordinates' bits hashed; the high half.
std::uint32_t weld_hash(const double point[3]) {
  const auto bits = [&](int k) { return std::bit_cast<std::uint64_t>(point[k]); };
  return static_cast<std::uint32_t>(hash_words(bits(0), bits(1), bits(2)) >> 32);
}

LoadedMesh repair_triangles(const std::string& name, std::vector<double> xyz,
                            std::vector<int> triangles, std::string format,
                            const ReadOptions& options) {
  const auto nv = static_cast<std::int64_t>(xyz.size() / 3);
  for (const int v : triangles)
    if (v < 0 || v >= nv) fail(name, "a triangle refers to vertex " + std::to_string(v) + " of " + std::to_string(nv));
  for (std::size_t k = 0; k < xyz.size(); k += 3)
    check_coordinates(name, &xyz[k], [&] { return "vertex " + std::to_string(k / 3); });
  RawMesh raw;
  raw.xyz = std::move(xyz);
  raw.triangles = std::move(triangles);
  return repair(name, std::move(raw), std::move(format), options);
}

LoadedMesh read_mesh(const std::string& path, const ReadOptions& options) {
  return read_mesh_bytes(path, read_regular_file(path, kMaxMeshFileBytes), options);
}

LoadedMesh read_mesh_bytes(const std::string& path, std::string_view view,
                           const ReadOptions& options) {
  if (view.empty()) fail(path, "empty file");
  const std::string ext = lower_extension(path);
  const bool ply_magic = view.substr(0, 4) == "ply\n" || view.substr(0, 5) == "ply\r\n";

  std::string format;
  RawMesh raw;
  if (ply_magic || ext == ".ply") {
    if (!ply_magic) fail(path, "not a PLY file (missing 'ply' magic)");
    raw = parse_ply(path, view, format);
  } else if (ext == ".obj") {
    format = "obj";
    raw = parse_obj(path, view);
  } else {
    // STL, or sniff an unknown extension. Binary STL headers may start with "solid" too: the
    // size 84 + 50·N decides, unless the file is plainly ASCII STL text.
    const bool solid = starts_with_solid(view);
    const bool text = looks_like_text(view);
    const bool ascii_stl = solid && text && view.find("facet") != std::string_view::npos;
    const bool stl = ext == ".stl";
    if ((stl || ascii_stl) && solid && text && !(binary_stl_size_matches(view) && !ascii_stl)) {
      format = "stl-ascii";
      raw = parse_stl_ascii(path, view);
    } else if (stl || binary_stl_size_matches(view)) {
      format = "stl-binary";
      raw = parse_stl_binary(path, view);
    } else if (text && has_obj_vertex_line(view)) {
      format = "obj";
      raw = parse_obj(path, view);
    } else {
      fail(path, "unsupported mesh format" + (ext.empty() ? std::string() : " " + quote_text(ext)) +
                     " (expected STL, OBJ or PLY)");
    }
  }
  return repair(path, std::move(raw), std::move(format), options);
}

}  // namespace flank::io
