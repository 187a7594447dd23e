// --lines files (fit, surface-driven start, paper §4.4): one cutter axis per row
// "x0 y0 z0 x1 y1 z1" (commas also accepted, '#' starts a comment), tip first, in the order
// the cutter passes them. --motion files (synth): the control points of a cubic motion.
#pragma once

#include <cstdint>
#include <string>
#include <string_view>
#include <vector>

#include "io/read_file.h"
#include "kernels/types.h"

namespace flank::io {

// A list of axes, not a mesh: 16 MiB is some 250,000 rows.
constexpr std::uint64_t kMaxLinesFileBytes = std::uint64_t{16} << 20;

// At least two axes, not all on one straight line. Throws io::Error("NAME: problem"), with
// the file's bytes quoted safely.
std::vector<AxisRow> parse_lines_text(const std::string& name, std::string_view text);

// The same from a regular file of at most kMaxLinesFileBytes.
std::vector<AxisRow> read_lines_file(const std::string& path);

// Control points, not a mesh: 16 MiB is some 250,000 rows.
constexpr std::uint64_t kMaxMotionFileBytes = std::uint64_t{16} << 20;

// The control points of a cubic motion a(t), b(t), one pair per row "ax ay az bx by bz"
// (blanks only), at least 4 rows, not all on one straight line.
struct ControlPoints {
  Points a, b;
};
// Throws io::Error("NAME: problem").
ControlPoints parse_motion_text(const std::string& name, std::string_view text);
// The same from a regular file of at most kMaxMotionFileBytes.
ControlPoints read_motion_file(const std::string& path);

}  // namespace flank::io
