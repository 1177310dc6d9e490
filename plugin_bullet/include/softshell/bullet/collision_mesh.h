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
namespace internal {
class ShellShape;
}

/// How a collision mesh is built.
struct CollisionMeshSettings {
  /// Uniform refinement level of the tessellation (0..8): 2 * 4^level triangles per quad face.
  /// Higher follows the limit surface more closely (chordal error falls about 4x a level) and costs
  /// more to refit after a deformation.
  int level = 3;
  /// Collision margin of the triangles (length unit, >= 0). Bullet's triangle meshes work with 0.
  /// (The BVH is always Bullet's quantized one: the only kind Bullet can refit in place.)
  double margin = 0.0;
};

/// The limit surface of one control mesh as a Bullet `btBvhTriangleMeshShape`.
///
/// Triangle `t` of the Bullet shape is triangle `t` of `tessellation()` (one mesh part, part id
/// 0), so a contact's triangle index and barycentric position map straight to the control face
/// and `(u, v)` through the quadtree path (`surface_point`). Vertex positions are in the shell's
/// local frame (the frame of its control points), as single-precision floats that Bullet reads in
/// place.
///
/// Double-buffered: there are two shapes, each with its own vertex buffer and quantized BVH over
/// the same triangles. `prepare` moves the hidden one to a deformed limit surface (one sparse
/// product with the tessellation's limit matrix, then a bottom-up BVH refit) while Bullet keeps
/// using the visible one, so it can run on a worker thread during `stepSimulation`; `commit`
/// makes it the visible one in O(1). After a commit `shape()` is the other object: point the
/// collision object at it (`btCollisionObject::setCollisionShape`). `update` does both at once.
///
/// Ownership: the mesh owns both shapes and their buffers; a `btCollisionObject` using `shape()`
/// must not outlive it. Not copyable or movable (Bullet holds pointers into it).
/// Thread-safety: `prepare` may run on one other thread while Bullet and the const members use the
/// visible shape; everything else (`commit`, `update`, `reset`, and `tessellation()` /
/// `normals()`, which refresh lazily) belongs to one thread, between `stepSimulation` calls, and
/// not while `prepare` runs for `commit` / `update` / `reset`.
class CollisionMesh {
 public:
  /// Tessellates `evaluator`'s rest limit surface and builds both shapes and their BVHs.
  /// kInvalidArgument for a level out of 0..8 or a negative / non-finite margin.
  static Result<std::unique_ptr<CollisionMesh>> create(const LimitEvaluator& evaluator,
                                                       const CollisionMeshSettings& settings = {});
  ~CollisionMesh();
  CollisionMesh(const CollisionMesh&) = delete;
  CollisionMesh& operator=(const CollisionMesh&) = delete;

  /// The visible Bullet shape (static). Changes identity on every `commit` / `update` / `reset`.
  btBvhTriangleMeshShape& shape();
  const btBvhTriangleMeshShape& shape() const;

  /// The SDK tessellation: root face, sub-face and quadtree path of every quad, double-precision
  /// vertices and unit normals of the visible shape. Brought up to date on the first call after
  /// a commit (the collision buffers do not need it), so that call costs a limit evaluation.
  const Tessellation& tessellation() const;
  const CollisionMeshSettings& settings() const { return settings_; }
  int32_t num_triangles() const { return static_cast<int32_t>(indices_.size() / 3); }
  int32_t num_vertices() const;

  /// Rendering data of the visible shape, ready for a GPU buffer: vertex positions (x, y, z
  /// floats, #vertices * 3, shell-local frame, length unit; the buffer Bullet collides with),
  /// unit normals (same layout; computed on the first call after a commit) and triangle indices
  /// (#triangles * 3, counter-clockwise seen from the normal side).
  std::span<const float> positions() const;
  std::span<const float> normals() const;
  std::span<const int32_t> indices() const { return indices_; }
  /// Incremented by every commit: re-upload the buffers when it changes.
  uint64_t version() const { return version_; }

  /// Barycentric weights (summing to 1, each in [0, 1]) of the point of triangle `triangle`
  /// closest to `local_point` (shell-local frame, visible shape). Throws
  /// `Exception(kInvalidArgument)` for a triangle index out of range.
  std::array<double, 3> barycentric(int32_t triangle, const Vec3& local_point) const;

  /// The surface point `(face, subface, u, v)` of a point on triangle `triangle` (e.g. a contact),
  /// through its barycentric weights and the quad's quadtree path (paper Section 5.1). Throws
  /// `Exception(kInvalidArgument)` for a triangle index out of range.
  SurfacePoint surface_point(int32_t triangle, const Vec3& local_point) const;

  /// Moves the hidden shape to the limit surface of the deformed control points
  /// `control_positions` (#control points, shell-local frame) and refits its BVH. Replaces an
  /// earlier prepared, uncommitted shape. Throws `Exception(kInvalidArgument)` for a wrong count
  /// or non-finite positions (and then leaves nothing prepared).
  void prepare(std::vector<Vec3> control_positions);
  /// True if a prepared shape waits for `commit`.
  bool prepared() const { return prepared_; }
  /// Makes the prepared shape the visible one (O(1)); false if nothing was prepared.
  bool commit();

  /// `prepare` + `commit`.
  void update(std::vector<Vec3> control_positions);
  /// Back to the rest shape (`update` with the rest control points).
  void reset();

  /// The control points the visible shape is the limit surface of (#control points).
  const std::vector<Vec3>& control_positions() const;

  /// Axis-aligned bounds of the visible vertices (shell-local frame).
  void bounds(Vec3& out_min, Vec3& out_max) const;

 private:
  struct Buffer;
  CollisionMesh(Tessellation tessellation, const CollisionMeshSettings& settings, std::vector<Vec3> rest_positions);
  void sync() const;
  const Buffer& front() const { return *buffers_[front_]; }

  mutable Tessellation tessellation_;  // brought up to date lazily (sync)
  mutable bool tessellation_stale_ = false;
  mutable bool normals_stale_ = false;
  const Eigen::SparseMatrix<double, Eigen::RowMajor>* limit_ = nullptr;  // tessellation_'s, built at create
  CollisionMeshSettings settings_;
  std::vector<Vec3> rest_positions_;  // control points of the rest shape (for reset)
  std::vector<int32_t> indices_;
  mutable std::vector<float> normals_;
  double size_ = 0.0;  // rest bounding diagonal
  std::unique_ptr<Buffer> buffers_[2];
  int front_ = 0;
  bool prepared_ = false;
  uint64_t version_ = 0;
};

}  // namespace softshell::bullet
