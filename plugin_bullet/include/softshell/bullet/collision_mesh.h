#pragma once
/// \file
/// \brief `CollisionMesh`: a shell's limit surface as a static Bullet triangle mesh
/// (`btBvhTriangleMeshShape` over the SDK `Tessellation`) that follows the deformation in place.

#include <array>
#include <cstdint>
#include <memory>
#include <span>
#include <vector>

#include "softshell/control_mesh.h"
#include "softshell/limit_evaluator.h"
#include "softshell/result.h"
#include "softshell/tessellation.h"

class btBvhTriangleMeshShape;
class btTriangleIndexVertexArray;

namespace softshell::bullet {

/// How a collision mesh is built.
struct CollisionMeshSettings {
  /// Uniform refinement level of the tessellation (0..8): 2 * 4^level triangles per quad face.
  /// Higher follows the limit surface more closely (chordal error falls about 4x a level) and costs
  /// more to refit after a deformation.
  int level = 3;
  /// Collision margin of the triangles (length unit, >= 0). Bullet's triangle meshes work with 0.
  double margin = 0.0;
  /// Use Bullet's quantized (16-bit) BVH nodes: a third of the memory, same queries.
  bool quantized_bvh = true;
};

/// The limit surface of one control mesh as a Bullet `btBvhTriangleMeshShape`.
///
/// Triangle `t` of the Bullet shape is triangle `t` of `tessellation()` (one mesh part, part id
/// 0), so a contact's triangle index and barycentric position map straight to the control face
/// and `(u, v)` through the quadtree path (`surface_point`). Vertex positions are in the shell's
/// local frame (the frame of its control points), as single-precision floats that Bullet reads in
/// place; `update` moves them to a deformed limit surface and refits the BVH, so the shape object
/// and every pointer to it stay valid.
///
/// Ownership: the mesh owns the shape and its vertex/index buffers; a `btCollisionObject` using
/// `shape()` must not outlive it. Not copyable or movable (Bullet holds pointers into it).
/// Thread-safety: const members may run concurrently with each other; `update` and `reset` must
/// not run while Bullet uses the shape (call them between `stepSimulation` calls).
class CollisionMesh {
 public:
  /// Tessellates `evaluator`'s rest limit surface and builds the shape and its BVH.
  /// kInvalidArgument for a level out of 0..8 or a negative / non-finite margin.
  static Result<std::unique_ptr<CollisionMesh>> create(const LimitEvaluator& evaluator,
                                                       const CollisionMeshSettings& settings = {});
  ~CollisionMesh();
  CollisionMesh(const CollisionMesh&) = delete;
  CollisionMesh& operator=(const CollisionMesh&) = delete;

  /// The Bullet shape (static; attach it to a `btCollisionObject`).
  btBvhTriangleMeshShape& shape();
  const btBvhTriangleMeshShape& shape() const;

  /// The SDK tessellation: root face, sub-face and quadtree path of every quad, double-precision
  /// vertices and unit normals of the current shape.
  const Tessellation& tessellation() const { return tessellation_; }
  const CollisionMeshSettings& settings() const { return settings_; }
  int32_t num_triangles() const { return static_cast<int32_t>(indices_.size() / 3); }
  int32_t num_vertices() const { return static_cast<int32_t>(positions_.size() / 3); }

  /// Rendering data of the current shape, ready for a GPU buffer: vertex positions (x, y, z
  /// floats, #vertices * 3, shell-local frame, length unit), unit normals (same layout) and
  /// triangle indices (#triangles * 3, counter-clockwise seen from the normal side).
  std::span<const float> positions() const { return positions_; }
  std::span<const float> normals() const { return normals_; }
  std::span<const int32_t> indices() const { return indices_; }
  /// Incremented by every `update` / `reset`: re-upload the buffers when it changes.
  uint64_t version() const { return version_; }

  /// Barycentric weights (summing to 1, each in [0, 1]) of the point of triangle `triangle`
  /// closest to `local_point` (shell-local frame, current shape). Throws
  /// `Exception(kInvalidArgument)` for a triangle index out of range.
  std::array<double, 3> barycentric(int32_t triangle, const Vec3& local_point) const;

  /// The surface point `(face, subface, u, v)` of a point on triangle `triangle` (e.g. a contact),
  /// through its barycentric weights and the quad's quadtree path (paper Section 5.1). Throws
  /// `Exception(kInvalidArgument)` for a triangle index out of range.
  SurfacePoint surface_point(int32_t triangle, const Vec3& local_point) const;

  /// Moves the vertices to the limit surface of the deformed control points `control_positions`
  /// (#control points, shell-local frame), recomputes the normals and refits the BVH in place.
  /// Throws `Exception(kInvalidArgument)` for a wrong count or non-finite positions.
  void update(const std::vector<Vec3>& control_positions);

  /// Back to the rest shape.
  void reset();

  /// Axis-aligned bounds of the current vertices (shell-local frame).
  void bounds(Vec3& out_min, Vec3& out_max) const;

 private:
  CollisionMesh(Tessellation tessellation, const CollisionMeshSettings& settings, std::vector<Vec3> rest_positions);
  void copy_from_tessellation();
  void refit();

  Tessellation tessellation_;
  CollisionMeshSettings settings_;
  std::vector<Vec3> rest_positions_;  // control points of the rest shape (for reset)
  std::vector<float> positions_;   // btScalar is float in Debian's (single precision) Bullet
  std::vector<float> normals_;
  std::vector<int32_t> indices_;
  std::unique_ptr<btTriangleIndexVertexArray> mesh_interface_;
  std::unique_ptr<btBvhTriangleMeshShape> shape_;
  uint64_t version_ = 0;
};

}  // namespace softshell::bullet
