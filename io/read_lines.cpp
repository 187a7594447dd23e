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

}  // namespace flank::io
