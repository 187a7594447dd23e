// flank info MESH: what the reader made of a mesh (or of a STEP/IGES file's faces, tessellated as
// decompose would), so a machinist can trust it before a run.
#include <CLI/CLI.hpp>
#include <cstdio>

#include "cli/commands.h"
#include "cli/common.h"
#include "io/cad.h"
#include "io/read_mesh.h"

namespace flank::cli {

void register_info(CLI::App& app, int* exit_code) {
  auto* cmd = app.add_subcommand("info", "Read a mesh, repair what is safe to repair, and report it");
  auto args = std::make_shared<PatchArgs>();
  cmd->add_option("MESH", args->mesh, "Design surface: STL (ASCII/binary), OBJ or PLY mesh, or STEP/IGES B-rep")->required();
  cmd->add_option("--faces", args->faces, "STEP/IGES only: the faces to tessellate, by index (e.g. 1,3,7-9; default all)");
  cmd->add_option("--tolerance", args->tolerance, "STEP/IGES only: the tolerance the tessellation serves, in mm");
  cmd->add_option("--tolerance-rel", args->tolerance_rel,
                  "STEP/IGES only: the same as a fraction of the diagonal (default 1e-4)");
  cmd->add_flag("--flip", args->flip, "Reverse the surface orientation (tools live on the normals' side)");
  set_action(cmd, exit_code, [=] {
    const std::string* mesh_path = &args->mesh;
    if (!io::is_cad_path(args->mesh) && (args->tolerance || args->tolerance_rel))
      throw UsageError("--tolerance and --tolerance-rel set the tessellation of a STEP or IGES file; " +
                       args->mesh + " is a mesh");
    Progress quiet("info", true);
    const Design design = read_design(*args, quiet, /*count_components=*/true);
    if (design.cad) {
      const io::CadPart& part = *design.part;
      std::printf("file            %s (%s, %zu faces)\n", printable(args->mesh).c_str(), part.format().c_str(),
                  part.faces().size());
      std::printf("face  surface     area mm^2     bbox min                          bbox max\n");
      for (const io::CadFace& f : part.faces())
        std::printf("%4d  %-10s  %-12.6g  [%.6g %.6g %.6g]  [%.6g %.6g %.6g]%s%s\n", f.index, f.surface.c_str(),
                    f.area, f.min.x(), f.min.y(), f.min.z(), f.max.x(), f.max.y(), f.max.z(),
                    part.face_name(f.index).empty() ? "" : "  ", printable(part.face_name(f.index)).c_str());
    }
    const io::LoadedMesh& lm = design.lm;
    const auto& r = lm.report;
    const BoundingBox box = bounding_box(lm.mesh);
    if (!design.cad) std::printf("file            %s (%s)\n", printable(*mesh_path).c_str(), r.format.c_str());
    std::printf("vertices        %d (file: %d, welded: %d, unused removed: %d)\n",
                lm.mesh.vertex_count(), r.input_vertices, r.welded_vertices, r.unused_vertices);
    std::printf("triangles       %d (file: %d, degenerate dropped: %d, duplicates dropped: %d)\n",
                lm.mesh.face_count(), r.input_faces, r.degenerate_faces, r.duplicate_faces);
    std::printf("orientation     %s, %d faces flipped to agree\n",
                r.orientable ? "consistent" : "NOT orientable", r.flipped_faces);
    std::printf("components      %d\n", r.components);
    std::printf("boundary edges  %d\n", r.boundary_edges);
    std::printf("non-manifold    %d edges\n", r.non_manifold_edges);
    std::printf("bbox            [%.6g %.6g %.6g] .. [%.6g %.6g %.6g]\n", box.min.x(), box.min.y(),
                box.min.z(), box.max.x(), box.max.y(), box.max.z());
    std::printf("bbox diagonal   %.6g mm\n", box.diagonal());
    std::printf("area            %.6g mm^2\n", total_area(lm.mesh));
    if (design.cad) {
      std::printf("tessellated     %zu faces for a tolerance of %.6g mm: chord deviation %.6g mm (asked %.6g)\n",
                  design.faces.size(), design.tolerance, design.chord_deviation, design.chord_target);
    } else {
      std::printf("default tol     %.6g mm (1e-4 x diagonal)\n", 1e-4 * box.diagonal());
    }
    return 0;
  });
}

}  // namespace flank::cli
