#include "io/read_lines.h"

namespace flank::io {

std::vector<AxisRow> parse_lines_text(const std::string& name, std::string_view text) {
  std::vector<AxisRow> rows = parse_axis_rows(name, text, /*commas=*/true);
  if (rows.size() < 2) throw Error(name + ": needs at least two lines, in motion order");
  require_sweep(name, rows, "lines");
  return rows;
}

std::vector<AxisRow> read_lines_file(const std::string& path) {
  return parse_lines_text(path, read_regular_file(path, kMaxLinesFileBytes));
}

ControlPoints parse_motion_text(const std::string& name, std::string_view text) {
  const std::vector<AxisRow> rows = parse_axis_rows(name, text, /*commas=*/false);
  if (rows.size() < 4)
    throw Error(name + ": " + std::to_string(rows.size()) +
                " control point rows; a cubic motion needs at least 4");
  require_sweep(name, rows, "control point rows");
  ControlPoints out;
  const auto count = static_cast<Eigen::Index>(rows.size());
  out.a.resize(count, 3);
  out.b.resize(count, 3);
  for (Eigen::Index i = 0; i < count; ++i) {
    out.a.row(i) = rows[i].a.transpose();
    out.b.row(i) = rows[i].b.transpose();
  }
  return out;
}

ControlPoints read_motion_file(const std::string& path) {
  return parse_motion_text(path, read_regular_file(path, kMaxMotionFileBytes));
}

}  // namespace flank::io
