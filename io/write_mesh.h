// Writing files: every file is written to a temporary created exclusively beside it and
// renamed into place, so a failure never leaves a half-written output (DESIGN "Command line").
#pragma once

#include <filesystem>
#include <functional>
#include <ostream>
#include <string>

#include "kernels/mesh.h"

namespace flank::io {

// Writes through `fill` into a mkstemp temporary beside `path`, flushes, renames onto `path`.
// Throws io::Error (and removes the temporary) if anything fails.
void write_file_atomic(const std::filesystem::path& path,
                       const std::function<void(std::ostream&)>& fill);
// The same with the whole file already in memory (no copy through a stream).
void write_file_atomic(const std::filesystem::path& path, const std::string& data);

// A plain triangle mesh, format by extension: .stl (binary), .obj, .ply (binary little-endian).
void write_mesh(const std::filesystem::path& path, const Mesh& mesh);

}  // namespace flank::io
