// report.html: one self-contained page a person opens in any browser, offline, to judge a run
// by looking at it: the design surface coloured by patch, Ω's signed error as a heat map, each
// cutter moving along its motion, and the numbers beside the picture (issue 12).
//
// The page is the front end of report/web (three.js from npm, bundled by esbuild at build
// time and embedded in this library) with the run's data spliced in as one JSON object whose
// meshes and motions are little-endian typed arrays in base64 (format flank-report/1, read by
// report/web/src/data.js).
#pragma once

#include <filesystem>
#include <vector>

#include "kernels/mesh.h"
#include "report/write.h"
#include "solver/patch.h"

namespace flank::report {

// Axis positions a(t), b(t) per patch in the page (steps + 1 of them): enough for a smooth
// slider and play-back, a few kB per patch.
inline constexpr int kReportMotionSteps = 240;

// Writes report.html through io::write_file_atomic; throws io::Error on failure.
// `vertex_patch`: the covering patch per vertex of `mesh` (−1 uncovered).
void write_report_html(const std::filesystem::path& path, const RunInfo& run,
                       const std::vector<Patch>& patches, const Mesh& mesh,
                       const std::vector<int>& vertex_patch);

}  // namespace flank::report
