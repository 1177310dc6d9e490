#pragma once
// ShellShape: a btBvhTriangleMeshShape whose BVH is refitted in one pass over our own vertex and
// index buffers (internal to softshell::bullet).
//
// Rationale: btBvhTriangleMeshShape::refitTree refits the quantized nodes and then recomputes the
// local bounds with six support-vertex queries over every triangle (recalcLocalAabb); on a
// 14k-triangle shell that is milliseconds per deformation. Here the node bounds are recomputed
// bottom-up straight from the float buffers Bullet reads (the same algorithm as
// btOptimizedBvh::updateBvhNodes: leaves from their triangle, internal nodes as the union of their
// children, subtree headers from their roots) and the local bounds are set from the vertex bounds
// computed while writing the vertices.

#include <BulletCollision/CollisionShapes/btBvhTriangleMeshShape.h>

namespace softshell::bullet::internal {

class ShellShape final : public btBvhTriangleMeshShape {
 public:
  BT_DECLARE_ALIGNED_ALLOCATOR();

  /// Builds a quantized BVH over `mesh` (which must be one part of float vertices and int32 indices).
  explicit ShellShape(btStridingMeshInterface* mesh) : btBvhTriangleMeshShape(mesh, true, true) {}

  /// Refits every node to the current vertices; `lo`/`hi` are their bounds (local frame).
  /// `quantization_margin` enlarges the quantization range (length unit, > 0).
  void refit(const float* positions, const int* indices, const btVector3& lo, const btVector3& hi,
             btScalar quantization_margin);
};

}  // namespace softshell::bullet::internal
