#include "softshell/bullet/collision_mesh.h"

#include <algorithm>
#include <cmath>
#include <limits>
#include <string>
#include <type_traits>

#include <BulletCollision/CollisionShapes/btBvhTriangleMeshShape.h>
#include <BulletCollision/CollisionShapes/btTriangleIndexVertexArray.h>

namespace softshell::bullet {

static_assert(std::is_same_v<btScalar, float>,
              "softshell::bullet is built for single-precision Bullet (Debian's build): the vertex buffer "
              "Bullet reads in place is float");

CollisionMesh::CollisionMesh(Tessellation tessellation, const CollisionMeshSettings& settings,
                             std::vector<Vec3> rest_positions)
    : tessellation_(std::move(tessellation)), settings_(settings), rest_positions_(std::move(rest_positions)) {}

CollisionMesh::~CollisionMesh() = default;

Result<std::unique_ptr<CollisionMesh>> CollisionMesh::create(const LimitEvaluator& evaluator,
                                                             const CollisionMeshSettings& settings) {
  return capture([&]() -> std::unique_ptr<CollisionMesh> {
    if (settings.level < 0 || settings.level > 8) {
      fail(ErrorCode::kInvalidArgument,
           "collision mesh level " + std::to_string(settings.level) + " is out of range (0..8)");
    }
    if (!std::isfinite(settings.margin) || settings.margin < 0.0) {
      fail(ErrorCode::kInvalidArgument, "collision margin must be finite and >= 0");
    }
    auto tessellation = Tessellation::create(evaluator, settings.level);
    if (!tessellation) throw Exception(tessellation.error());
    if (tessellation->triangles().empty()) {
      fail(ErrorCode::kInvalidArgument, "the mesh has no limit surface to collide with (only ghost faces)");
    }
    std::unique_ptr<CollisionMesh> mesh(new CollisionMesh(std::move(*tessellation), settings, evaluator.mesh().positions()));

    // Index buffer: triangle t of Bullet's mesh is triangle t of the tessellation.
    const auto& triangles = mesh->tessellation_.triangles();
    mesh->indices_.reserve(triangles.size() * 3);
    for (const auto& tri : triangles) mesh->indices_.insert(mesh->indices_.end(), tri.begin(), tri.end());
    mesh->copy_from_tessellation();

    // One mesh part over our own buffers; Bullet reads them in place.
    mesh->mesh_interface_ = std::make_unique<btTriangleIndexVertexArray>(
        mesh->num_triangles(), mesh->indices_.data(), static_cast<int>(3 * sizeof(int32_t)), mesh->num_vertices(),
        mesh->positions_.data(), static_cast<int>(3 * sizeof(float)));
    mesh->shape_ = std::make_unique<btBvhTriangleMeshShape>(mesh->mesh_interface_.get(), settings.quantized_bvh, true);
    mesh->shape_->setMargin(static_cast<btScalar>(settings.margin));
    return mesh;
  });
}

btBvhTriangleMeshShape& CollisionMesh::shape() { return *shape_; }
const btBvhTriangleMeshShape& CollisionMesh::shape() const { return *shape_; }

void CollisionMesh::copy_from_tessellation() {
  const auto& x = tessellation_.vertices();
  const auto& n = tessellation_.normals();
  positions_.resize(3 * x.size());
  normals_.resize(3 * n.size());
  for (size_t i = 0; i < x.size(); ++i) {
    for (int a = 0; a < 3; ++a) {
      positions_[3 * i + static_cast<size_t>(a)] = static_cast<float>(x[i][a]);
      normals_[3 * i + static_cast<size_t>(a)] = static_cast<float>(n[i][a]);
    }
  }
  ++version_;
}

void CollisionMesh::bounds(Vec3& out_min, Vec3& out_max) const {
  Eigen::Vector3f lo = Eigen::Vector3f::Constant(std::numeric_limits<float>::max());
  Eigen::Vector3f hi = -lo;
  for (size_t i = 0; i + 2 < positions_.size(); i += 3) {
    const Eigen::Map<const Eigen::Vector3f> p(positions_.data() + i);
    lo = lo.cwiseMin(p);
    hi = hi.cwiseMax(p);
  }
  out_min = lo.cast<double>();
  out_max = hi.cast<double>();
}

void CollisionMesh::refit() {
  // A full refit re-quantizes the nodes over the new bounds, so a deformation may leave the
  // bounds the BVH was built with (a partial refit could not).
  Vec3 lo, hi;
  bounds(lo, hi);
  const btVector3 bt_lo(static_cast<btScalar>(lo.x()), static_cast<btScalar>(lo.y()), static_cast<btScalar>(lo.z()));
  const btVector3 bt_hi(static_cast<btScalar>(hi.x()), static_cast<btScalar>(hi.y()), static_cast<btScalar>(hi.z()));
  shape_->refitTree(bt_lo, bt_hi);
}

void CollisionMesh::update(const std::vector<Vec3>& control_positions) {
  for (const Vec3& p : control_positions) {
    if (!p.allFinite()) fail(ErrorCode::kInvalidArgument, "CollisionMesh::update: non-finite control position");
  }
  tessellation_.update(control_positions);  // checks the count
  copy_from_tessellation();
  refit();
}

void CollisionMesh::reset() {
  tessellation_.update(rest_positions_);
  copy_from_tessellation();
  refit();
}

std::array<double, 3> CollisionMesh::barycentric(int32_t triangle, const Vec3& local_point) const {
  if (triangle < 0 || triangle >= num_triangles()) {
    fail(ErrorCode::kInvalidArgument, "triangle index " + std::to_string(triangle) + " is out of range (" +
                                          std::to_string(num_triangles()) + " triangles)");
  }
  const auto corner = [&](int c) {
    const size_t v = static_cast<size_t>(indices_[3 * static_cast<size_t>(triangle) + static_cast<size_t>(c)]);
    return Vec3(positions_[3 * v], positions_[3 * v + 1], positions_[3 * v + 2]);
  };
  const Vec3 a = corner(0), b = corner(1), c = corner(2);
  // Closest point on the triangle (Ericson, Real-Time Collision Detection, 5.1.5), as weights.
  const Vec3 ab = b - a, ac = c - a, ap = local_point - a;
  const double d1 = ab.dot(ap), d2 = ac.dot(ap);
  if (d1 <= 0.0 && d2 <= 0.0) return {1.0, 0.0, 0.0};
  const Vec3 bp = local_point - b;
  const double d3 = ab.dot(bp), d4 = ac.dot(bp);
  if (d3 >= 0.0 && d4 <= d3) return {0.0, 1.0, 0.0};
  const double vc = d1 * d4 - d3 * d2;
  if (vc <= 0.0 && d1 >= 0.0 && d3 <= 0.0) {
    const double w = d1 / (d1 - d3);
    return {1.0 - w, w, 0.0};
  }
  const Vec3 cp = local_point - c;
  const double d5 = ab.dot(cp), d6 = ac.dot(cp);
  if (d6 >= 0.0 && d5 <= d6) return {0.0, 0.0, 1.0};
  const double vb = d5 * d2 - d1 * d6;
  if (vb <= 0.0 && d2 >= 0.0 && d6 <= 0.0) {
    const double w = d2 / (d2 - d6);
    return {1.0 - w, 0.0, w};
  }
  const double va = d3 * d6 - d5 * d4;
  if (va <= 0.0 && (d4 - d3) >= 0.0 && (d5 - d6) >= 0.0) {
    const double w = (d4 - d3) / ((d4 - d3) + (d5 - d6));
    return {0.0, 1.0 - w, w};
  }
  const double denom = va + vb + vc;
  if (!(denom > 0.0)) return {1.0 / 3.0, 1.0 / 3.0, 1.0 / 3.0};  // degenerate triangle
  const double v = vb / denom, w = vc / denom;
  return {1.0 - v - w, v, w};
}

SurfacePoint CollisionMesh::surface_point(int32_t triangle, const Vec3& local_point) const {
  return tessellation_.surface_point(triangle, barycentric(triangle, local_point));
}

}  // namespace softshell::bullet
