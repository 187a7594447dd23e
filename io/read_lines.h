// --lines files (fit, surface-driven start, paper §4.4): one cutter axis per row
// "x0 y0 z0 x1 y1 z1" (commas also accepted, '#' starts a comment), tip first, in the order
// the cutter passes them.
#pragma once

#include <cstdint>
#include <string>
#include <string_view>
#include <vector>

#include "io/read_file.h"

namespace flank::io {

// A list of axes, not a mesh: 16 MiB is some 250,000 rows.
constexpr std::uint64_t kMaxLinesFileBytes = std::uint64_t{16} << 20;

// At least two axes, not all on one straight line. Throws io::Error("NAME: problem"), with
// the file's bytes quoted safely.
std::vector<AxisRow> parse_lines_text(const std::string& name, std::string_view text);

// The same from a regular file of at most kMaxLinesFileBytes.
std::vector<AxisRow> read_lines_file(const std::string& path);

}  // namespace flank::io
