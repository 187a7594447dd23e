// Writing a run's results for the 40,000-triangle exact part (the cone 4→7 envelope of the
// Li–Mann–Bedi guides at 201 × 101 vertices, decomposed once with cones): report.html against
// patches.json and the two PLY files, which carry the same meshes. Counter `MB`: the size of
// the file written (issue 12: report.html of a 40k-triangle part under 10 MB, written in
// under 1 s).
#include <benchmark/benchmark.h>

#include <filesystem>
#include <memory>
#include <string>
#include <unistd.h>

#include "kernels/surface_index.h"
#include "report/write.h"
#include "report/write_html.h"
#include "solver/decompose.h"
#include "solver/synth.h"

namespace flank {
namespace {

namespace fs = std::filesystem;

struct Run {
  Mesh mesh;
  DecomposeResult result;
  report::RunInfo info;
};

const Run& forty_k_run() {
  static std::unique_ptr<Run> run;
  if (!run) {
    run = std::make_unique<Run>();
    SynthOptions so;
    so.rows = 201;
    so.cols = 101;
    run->mesh = synth_envelope(guide_motion(paper_guides(), kPaperToolLength), cone_profile(kPaperToolLength, 4, 7), so).mesh;
    const SurfaceIndex index(run->mesh);
    DecomposeOptions o;
    o.tolerance = 1e-4 * index.diagonal();
    o.kinds = {CutterKind::cone};
    run->result = decompose(index, o);
    report::RunInfo& info = run->info;
    info.command = "decompose";
    info.input_path = "part.stl";
    info.input_format = "stl-binary";
    info.vertices = run->mesh.vertex_count();
    info.triangles = run->mesh.face_count();
    info.bbox_diagonal = index.diagonal();
    info.tolerance = o.tolerance;
    info.coverage_fraction = run->result.coverage;
    info.total_area = run->result.total_area;
    info.coverage_curve = run->result.coverage_curve;
  }
  return *run;
}

fs::path scratch(const std::string& name) {
  return fs::temp_directory_path() / ("flank_bench_" + std::to_string(::getpid()) + "_" + name);
}

template <typename Write>
void time_writer(benchmark::State& state, const std::string& name, Write write) {
  const Run& run = forty_k_run();
  const fs::path path = scratch(name);
  for (auto _ : state) write(path, run);
  state.counters["MB"] = static_cast<double>(fs::file_size(path)) / 1e6;
  state.counters["triangles"] = run.mesh.face_count();
  state.counters["patches"] = static_cast<double>(run.result.patches.size());
  fs::remove(path);
}

void BM_WriteReportHtml(benchmark::State& state) {
  time_writer(state, "report.html", [](const fs::path& path, const Run& run) {
    report::write_report_html(path, run.info, run.result.patches, run.mesh, run.result.vertex_patch);
  });
}
BENCHMARK(BM_WriteReportHtml)->UseRealTime()->Unit(benchmark::kMillisecond);

void BM_WritePatchesJson(benchmark::State& state) {
  time_writer(state, "patches.json", [](const fs::path& path, const Run& run) {
    report::write_patches_json(path, run.info, run.result.patches);
  });
}
BENCHMARK(BM_WritePatchesJson)->UseRealTime()->Unit(benchmark::kMillisecond);

// design.ply and envelopes.ply: the meshes report.html carries, in binary PLY.
void BM_WritePlys(benchmark::State& state) {
  time_writer(state, "design.ply", [](const fs::path& path, const Run& run) {
    report::write_design_ply(path, run.mesh, run.result.vertex_patch);
    report::write_envelopes_ply(path.string() + ".envelopes", run.result.patches, run.info.tolerance);
  });
  fs::remove(scratch("design.ply").string() + ".envelopes");
}
BENCHMARK(BM_WritePlys)->UseRealTime()->Unit(benchmark::kMillisecond);

}  // namespace
}  // namespace flank
