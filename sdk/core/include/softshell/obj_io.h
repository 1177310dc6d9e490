#pragma once
/// \file
/// \brief Wavefront OBJ reading and writing of control meshes (with OpenSubdiv's `t` tags) and of
/// triangle meshes.

#include <filesystem>
#include <string>
#include <string_view>
#include <vector>

#include "softshell/control_mesh.h"
#include "softshell/result.h"

namespace softshell {

/// Limits that protect the OBJ reader from hostile files.
struct ObjReadOptions {
  int64_t max_vertices = 50'000'000;      ///< more `v` lines than this is an error
  int64_t max_face_indices = 200'000'000;  ///< more face corners than this is an error
  int32_t max_face_size = 1024;            ///< a face with more corners than this is an error
  /// Also check the mesh for simulation (`find_mesh_issues`) and report the first problem in the
  /// file's terms: the line of the face or vertex concerned and OBJ's 1-based vertex numbers
  /// (kInvalidArgument or kUnprocessable, as `validate_mesh`).
  bool validate = false;
};

/// Parses OBJ text into a control mesh.
///
/// Understood: `v x y z [w]`, `f` with `v`, `v/vt`, `v//vn` and `v/vt/vn` corners and negative
/// (relative) indices, and OpenSubdiv's tags `t crease 2/1/0 v0 v1 s`, `t corner 1/1/0 v s` and
/// `t interpolateboundary 1/0/0 m` (m = 0: none, 1 or 2: edge-and-corner). Ignored: `vt`, `vn`,
/// `o`, `g`, `s`, `usemtl`, `mtllib`, comments, blank lines. Lines may end in `\` to continue.
///
/// Errors (kInvalidArgument) name the source, line number and what was expected. The result is
/// *not* validated for simulation; call `validate_mesh()` for that.
Result<ControlMesh> parse_obj(std::string_view text, std::string_view source_name = "<memory>",
                              const ObjReadOptions& options = {});

/// Reads and parses an OBJ file (kIoError if it cannot be read, e.g. it is a directory).
Result<ControlMesh> read_obj(const std::filesystem::path& path, const ObjReadOptions& options = {});

/// OBJ text of a control mesh: `v` lines with 17 significant digits (round-trips exactly), `f`
/// lines with 1-based indices, and `t` tags for creases, corners and the boundary mode.
std::string format_obj(const ControlMesh& mesh);

/// Writes `format_obj(mesh)` to a file.
Result<void> write_obj(const ControlMesh& mesh, const std::filesystem::path& path);

/// OBJ text of a triangle mesh (e.g. a tessellated limit surface), with optional per-vertex
/// normals (`vn`, same count as vertices) written as `f a//a b//b c//c`.
std::string format_triangles_obj(const std::vector<Vec3>& vertices,
                                 const std::vector<std::array<int32_t, 3>>& triangles,
                                 const std::vector<Vec3>& normals = {});

/// Writes `format_triangles_obj(...)` to a file.
Result<void> write_triangles_obj(const std::filesystem::path& path, const std::vector<Vec3>& vertices,
                                 const std::vector<std::array<int32_t, 3>>& triangles,
                                 const std::vector<Vec3>& normals = {});

}  // namespace softshell
