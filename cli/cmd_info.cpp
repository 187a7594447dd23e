// flank info MESH: what the reader made of a mesh, so a machinist can trust it before a run.
#include <CLI/CLI.hpp>
#include <cstdio>

#include "cli/commands.h"
#include "cli/common.h"
#include "io/read_mesh.h"

namespace flank::cli {

void register_info(CLI::App& app, int* exit_code) {
  auto* cmd = app.add_subcommand("info", "Read a mesh, repair what is safe to repair, and report it");
  auto mesh_path = std::make_shared<std::string>();
  auto flip = std::make_shared<bool>(false);
  cmd->add_option("MESH", *mesh_path, "Design surface: STL (ASCII/binary), OBJ or PLY")->required();
  cmd->add_flag("--flip", *flip, "Reverse the surface orientation (tools live on the normals' side)");
  set_action(cmd, exit_code, [=] {
    io::ReadOptions ro;
    ro.flip = *flip;
    const io::LoadedMesh lm = io::read_mesh(*mesh_path, ro);
    const auto& r = lm.report;
    const BoundingBox box = bounding_box(lm.mesh);
    std::printf("file            %s (%s)\n", printable(*mesh_path).c_str(), r.format.c_str());
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
    std::printf("default tol     %.6g mm (1e-4 x diagonal)\n", 1e-4 * box.diagonal());
    return 0;
  });
}

}  // namespace flank::cli
