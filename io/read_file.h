// Reading input files (mesh, --lines, --motion): the whole file, its rows of six numbers, and
// its bytes quoted in messages.
#pragma once

#include <algorithm>
#include <cerrno>
#include <charconv>
#include <cmath>
#include <cstdint>
#include <cstring>
#include <memory>
#include <string>
#include <string_view>
#include <system_error>
#include <vector>

#include "io/read_mesh.h"  // io::Error

namespace flank::io {

// `text` in single quotes, safe in a one-line message: bytes outside printable ASCII (ESC,
// newline, UTF-8 lead bytes) become '?', and the text is cut after `max` bytes.
inline std::string quote_text(std::string_view text, std::size_t max = 24) {
  std::string out = "'";
  for (std::size_t i = 0; i < text.size() && i < max; ++i) {
    const unsigned char c = static_cast<unsigned char>(text[i]);
    out += (c >= 0x20 && c < 0x7f) ? static_cast<char>(c) : '?';
  }
  if (text.size() > max) out += "...";
  return out + "'";
}

// A file's bytes, read whole by read_regular_file, in storage that nothing writes before the
// read does (a std::string of the size would be zeroed first, and reading through a small
// buffer copied every byte twice: 0.10 ms of Rotor 67 upper's 1.9 MB, 0.05 ms so). Its view
// lives as long as it does: pass read_regular_file(...) straight to a string_view parameter,
// or keep the FileBytes in a variable; a string_view initialised from the call dangles.
class FileBytes {
 public:
  std::string_view view() const { return {data_.get(), size_}; }
  operator std::string_view() const { return view(); }
  std::size_t size() const { return size_; }
  bool empty() const { return size_ == 0; }

 private:
  friend FileBytes read_regular_file(const std::string& path, std::uint64_t max_bytes);
  std::unique_ptr<char[]> data_;
  std::size_t size_ = 0;
};

// The whole content of `path`. Only a regular file of at most `max_bytes` is read: a FIFO
// would block and /dev/zero never ends, so anything else is refused from stat, and the
// file is opened non-blocking and checked again in case it was swapped in between. A large
// file is read in pieces side by side. Throws io::Error("PATH: problem").
FileBytes read_regular_file(const std::string& path, std::uint64_t max_bytes);

// A whole token as a finite decimal number. from_chars rather than strtod: it neither depends
// on the locale nor reads hexadecimal, and it raises no floating-point exception on overflow
// (the Debug tests trap those).
inline bool parse_finite(std::string_view token, double& value) {
  if (!token.empty() && token[0] == '+') token.remove_prefix(1);
  const char* end = token.data() + token.size();
  const auto [stop, ec] = std::from_chars(token.data(), end, value);
  return !token.empty() && ec == std::errc() && stop == end && std::isfinite(value);
}

// One row of a --lines or --motion file: the axis from a (the tip) to b.
struct AxisRow {
  Vec3 a, b;
  long long line = 0;  // in the file, from 1
};

// Rows of six numbers "ax ay az bx by bz": '#' starts a comment, blank rows are skipped,
// numbers are separated by blanks (and by commas when `commas`). Each row needs a != b.
// Throws io::Error("NAME: line N: problem").
inline std::vector<AxisRow> parse_axis_rows(const std::string& name, std::string_view text,
                                            bool commas) {
  const std::string_view separators = commas ? std::string_view(" \t\r\f\v,") : " \t\r\f\v";
  std::vector<AxisRow> rows;
  long long number = 0;
  while (!text.empty()) {
    const std::size_t newline = text.find('\n');
    std::string_view row = text.substr(0, newline);
    text.remove_prefix(newline == std::string_view::npos ? text.size() : newline + 1);
    ++number;
    row = row.substr(0, row.find('#'));
    std::string_view tokens[6];
    std::size_t count = 0;
    for (std::size_t i = row.find_first_not_of(separators); i != std::string_view::npos;) {
      const std::size_t j = std::min(row.find_first_of(separators, i), row.size());
      if (count < 6) tokens[count] = row.substr(i, j - i);
      ++count;
      i = row.find_first_not_of(separators, j);
    }
    if (count == 0) continue;
    const std::string where = name + ": line " + std::to_string(number) + ": ";
    if (count != 6)
      throw Error(where + "expected 6 numbers (ax ay az bx by bz), found " + std::to_string(count));
    double v[6];
    for (int k = 0; k < 6; ++k)
      if (!parse_finite(tokens[k], v[k])) throw Error(where + quote_text(tokens[k]) + " is not a finite number");
    AxisRow axis{Vec3(v[0], v[1], v[2]), Vec3(v[3], v[4], v[5]), number};
    if (axis.a == axis.b) throw Error(where + "a and b coincide (the axis has no length)");
    rows.push_back(axis);
  }
  return rows;
}

// Axes that all lie on one straight line only slide along it: they sweep no surface, and a
// motion built from them is degenerate (issue 14 rows 13, 15). "On it" is relative to the
// rows' extent, so that rounding in the file does not hide a repeated row. `rows_named` says
// what the rows are ("lines"). Throws io::Error("NAME: problem").
inline void require_sweep(const std::string& name, const std::vector<AxisRow>& rows,
                          const std::string& rows_named) {
  if (rows.empty()) return;
  const Vec3 origin = rows[0].a;
  const Vec3 u = (rows[0].b - rows[0].a).normalized();
  double extent = 0, off_axis = 0;
  for (const AxisRow& row : rows)
    for (const Vec3& p : {row.a, row.b}) {
      const Vec3 d = p - origin;
      extent = std::max(extent, d.norm());
      off_axis = std::max(off_axis, (d - d.dot(u) * u).norm());
    }
  if (off_axis <= 1e-9 * extent)
    throw Error(name + ": all " + std::to_string(rows.size()) + " " + rows_named +
                " lie on one straight line; a motion needs axes that sweep across the surface");
}

}  // namespace flank::io
