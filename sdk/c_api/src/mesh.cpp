// C ABI: control meshes and materials.

#include <cmath>
#include <string>
#include <vector>

#include "c_api_internal.h"
#include "softshell/material.h"
#include "softshell/mesh_validation.h"
#include "softshell/obj_io.h"
#include "softshell/softshell_c_bridge.h"

using namespace softshell;         // NOLINT(google-build-using-namespace): a .cpp of entry points
using namespace softshell::c_api;  // NOLINT(google-build-using-namespace)

extern "C" {

// ------------------------------------------------------------------------------------------------
// Control mesh

ss_status ss_mesh_create(const double* positions_xyz, int32_t num_vertices, const int32_t* face_sizes,
                         int32_t num_faces, const int32_t* face_indices, int32_t num_face_indices,
                         ss_mesh** out_mesh) {
  return guard("ss_mesh_create", [&] {
    required(out_mesh, "out_mesh");
    *out_mesh = nullptr;
    std::vector<Vec3> positions = read_xyz(positions_xyz, num_vertices, "positions_xyz");
    count_arg(num_faces, "num_faces");
    count_arg(num_face_indices, "num_face_indices");
    if (num_faces > 0) required(face_sizes, "face_sizes");
    if (num_face_indices > 0) required(face_indices, "face_indices");
    int64_t total = 0;
    for (int32_t f = 0; f < num_faces; ++f) {
      if (face_sizes[f] < 3) {
        fail(ErrorCode::kInvalidArgument, "face " + std::to_string(f) + " has " + std::to_string(face_sizes[f]) +
                                              " corners; a face needs at least 3");
      }
      total += face_sizes[f];
    }
    if (total != num_face_indices) {
      fail(ErrorCode::kInvalidArgument, "the face sizes add up to " + std::to_string(total) + " but " +
                                            std::to_string(num_face_indices) + " face indices were given");
    }
    for (int32_t k = 0; k < num_face_indices; ++k) {
      if (face_indices[k] < 0 || face_indices[k] >= num_vertices) {
        fail(ErrorCode::kInvalidArgument, "face index " + std::to_string(k) + " is " + std::to_string(face_indices[k]) +
                                              ", out of range (" + std::to_string(num_vertices) + " vertices)");
      }
    }
    *out_mesh = make_handle<ss_mesh>(std::make_shared<ControlMesh>(
        std::move(positions), std::vector<int32_t>(face_sizes, face_sizes + num_faces),
        std::vector<int32_t>(face_indices, face_indices + num_face_indices)));
  });
}

ss_status ss_mesh_read_obj(const char* path, ss_mesh** out_mesh) {
  return guard("ss_mesh_read_obj", [&] {
    required(out_mesh, "out_mesh");
    *out_mesh = nullptr;
    required(path, "path");
    *out_mesh = make_handle<ss_mesh>(std::make_shared<ControlMesh>(read_obj(path).value()));
  });
}

ss_status ss_mesh_write_obj(const ss_mesh* mesh, const char* path) {
  return guard("ss_mesh_write_obj", [&] {
    const auto m = live(mesh, "mesh");
    required(path, "path");
    write_obj(*m, path).value();
  });
}

void ss_mesh_destroy(ss_mesh* mesh) { destroy(mesh, "ss_mesh_destroy"); }

ss_status ss_mesh_counts(const ss_mesh* mesh, int32_t* out_num_vertices, int32_t* out_num_faces) {
  return guard("ss_mesh_counts", [&] {
    const auto m = live(mesh, "mesh");
    if (out_num_vertices) *out_num_vertices = m->num_vertices();
    if (out_num_faces) *out_num_faces = m->num_faces();
  });
}

ss_status ss_mesh_positions(const ss_mesh* mesh, double* out_xyz, int32_t capacity, int32_t* out_count) {
  return guard("ss_mesh_positions",
               [&] { write_xyz(live(mesh, "mesh")->positions(), out_xyz, capacity, out_count, "positions"); });
}

ss_status ss_mesh_set_positions(ss_mesh* mesh, const double* positions_xyz, int32_t count) {
  return guard("ss_mesh_set_positions", [&] {
    const auto m = live(mesh, "mesh");
    std::vector<Vec3> p = read_xyz(positions_xyz, count, "positions_xyz");
    if (count != m->num_vertices()) {
      fail(ErrorCode::kInvalidArgument,
           "expected " + std::to_string(m->num_vertices()) + " positions, got " + std::to_string(count));
    }
    m->positions() = std::move(p);
  });
}

ss_status ss_mesh_faces(const ss_mesh* mesh, int32_t* out_sizes, int32_t sizes_capacity, int32_t* out_num_faces,
                        int32_t* out_indices, int32_t indices_capacity, int32_t* out_num_indices) {
  return guard("ss_mesh_faces", [&] {
    const auto m = live(mesh, "mesh");
    required(out_num_faces, "out_num_faces");
    required(out_num_indices, "out_num_indices");
    count_arg(sizes_capacity, "sizes_capacity");
    count_arg(indices_capacity, "indices_capacity");
    const std::vector<int32_t> sizes = m->face_sizes();
    const std::vector<int32_t>& indices = m->face_indices();
    *out_num_faces = m->num_faces();
    *out_num_indices = static_cast<int32_t>(indices.size());
    // Check both before writing either.
    const bool query_sizes = out_sizes == nullptr && sizes_capacity == 0;
    const bool query_indices = out_indices == nullptr && indices_capacity == 0;
    if ((!query_sizes && sizes_capacity < *out_num_faces) || (!query_indices && indices_capacity < *out_num_indices)) {
      throw CStatus{SS_BUFFER_TOO_SMALL, "needs " + std::to_string(*out_num_faces) + " face sizes and " +
                                             std::to_string(*out_num_indices) + " face indices"};
    }
    int32_t n = 0;
    write_items(out_sizes, sizes_capacity, &n, sizes.size(), "face sizes",
                [&](int32_t* o) { std::copy(sizes.begin(), sizes.end(), o); });
    write_items(out_indices, indices_capacity, &n, indices.size(), "face indices",
                [&](int32_t* o) { std::copy(indices.begin(), indices.end(), o); });
  });
}

ss_status ss_mesh_set_boundary(ss_mesh* mesh, int32_t boundary) {
  return guard("ss_mesh_set_boundary", [&] {
    const auto m = live(mesh, "mesh");
    if (boundary != SS_BOUNDARY_EDGE_AND_CORNER && boundary != SS_BOUNDARY_NONE) {
      fail(ErrorCode::kInvalidArgument, "boundary must be SS_BOUNDARY_EDGE_AND_CORNER (0) or SS_BOUNDARY_NONE (1)");
    }
    m->set_boundary(boundary == SS_BOUNDARY_NONE ? BoundaryMode::kNone : BoundaryMode::kEdgeAndCorner);
  });
}

ss_status ss_mesh_add_crease(ss_mesh* mesh, int32_t v0, int32_t v1, float sharpness) {
  return guard("ss_mesh_add_crease", [&] {
    const auto m = live(mesh, "mesh");
    const int32_t n = m->num_vertices();
    if (v0 < 0 || v0 >= n || v1 < 0 || v1 >= n || v0 == v1) {
      fail(ErrorCode::kInvalidArgument, "a crease needs two different control points in 0.." + std::to_string(n - 1));
    }
    if (!std::isfinite(sharpness) || sharpness < 0.0f) {
      fail(ErrorCode::kInvalidArgument, "crease sharpness must be finite and >= 0");
    }
    m->creases().push_back(Crease{v0, v1, sharpness});
  });
}

ss_status ss_mesh_validate(const ss_mesh* mesh) {
  return guard("ss_mesh_validate", [&] { validate_mesh(*live(mesh, "mesh")).value(); });
}

// ------------------------------------------------------------------------------------------------
// Materials

void ss_material_default(ss_material* out) {
  if (out) *out = to_c(Material{});
}

ss_status ss_material_check(const ss_material* m) {
  return guard("ss_material_check", [&] { material(m, "material").check().value(); });
}

ss_status ss_material_preset(const char* name, double thickness, ss_material* out_material) {
  return guard("ss_material_preset", [&] {
    required(name, "name");
    required(out_material, "out_material");
    *out_material = to_c(softshell::material_preset(name, thickness).value());
  });
}

int32_t ss_material_preset_count(void) { return static_cast<int32_t>(material_presets().size()); }

ss_status ss_material_preset_at(int32_t index, const char** out_name, const char** out_description,
                                ss_material* out_material, double* out_yield_strength) {
  return guard("ss_material_preset_at", [&] {
    const auto& presets = material_presets();
    if (index < 0 || static_cast<size_t>(index) >= presets.size()) {
      fail(ErrorCode::kInvalidArgument, "preset index " + std::to_string(index) + " is out of range (" +
                                            std::to_string(presets.size()) + " presets)");
    }
    const MaterialPreset& p = presets[static_cast<size_t>(index)];
    if (out_name) *out_name = p.name.c_str();  // the presets are static: the strings live forever
    if (out_description) *out_description = p.description.c_str();
    if (out_material) *out_material = to_c(p.material);
    if (out_yield_strength) *out_yield_strength = p.yield_strength;
  });
}

}  // extern "C"
