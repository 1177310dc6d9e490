#include "softshell/bullet/collision_mesh.h"

#include <algorithm>
#include <cmath>
#include <limits>
#include <string>
#include <type_traits>

#include <BulletCollision/CollisionShapes/btTriangleIndexVertexArray.h>

#include "shell_shape.h"

namespace softshell::bullet {

static_assert(std::is_same_v<btScalar, float>,
              "softshell::bullet is built for single-precision Bullet (Debian's build): the vertex buffer "
              "Bullet reads in place is float");

namespace {

btVector3 to_bt(const Vec3& v) {
  return btVector3(static_cast<btScalar>(v.x()), static_cast<btScalar>(v.y()), static_cast<btScalar>(v.z()));
}

}  // namespace

// One of the two shapes: its vertices, BVH and the control points it shows.
struct CollisionMesh::Buffer {
  std::vector<Vec3> control_positions;
  std::vector<float> positions;  // btScalar is float in Debian's (single precision) Bullet
  Vec3 lo = Vec3::Zero(), hi = Vec3::Zero();
  std::unique_ptr<btTriangleIndexVertexArray> mesh_interface;
  std::unique_ptr<internal::ShellShape> shape;
};

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
    mesh->limit_ = &mesh->tessellation_.limit_matrix();  // built now, not on the first deformation
    mesh->size_ = evaluator.mesh().bounding_diagonal();

    // Index buffer: triangle t of Bullet's mesh is triangle t of the tessellation.
    const auto& triangles = mesh->tessellation_.triangles();
    mesh->indices_.reserve(triangles.size() * 3);
    for (const auto& tri : triangles) mesh->indices_.insert(mesh->indices_.end(), tri.begin(), tri.end());

    // Both buffers start as the rest shape, each with its own BVH over it.
    const auto& x = mesh->tessellation_.vertices();
    const auto& n = mesh->tessellation_.normals();
    mesh->normals_.resize(3 * n.size());
    for (size_t i = 0; i < n.size(); ++i) {
      for (int a = 0; a < 3; ++a) mesh->normals_[3 * i + static_cast<size_t>(a)] = static_cast<float>(n[i][a]);
    }
    for (auto& buffer : mesh->buffers_) {
      buffer = std::make_unique<Buffer>();
      buffer->control_positions = mesh->rest_positions_;
      buffer->positions.resize(3 * x.size());
      buffer->lo = Vec3::Constant(std::numeric_limits<double>::max());
      buffer->hi = -buffer->lo;
      for (size_t i = 0; i < x.size(); ++i) {
        for (int a = 0; a < 3; ++a) buffer->positions[3 * i + static_cast<size_t>(a)] = static_cast<float>(x[i][a]);
        buffer->lo = buffer->lo.cwiseMin(x[i]);
        buffer->hi = buffer->hi.cwiseMax(x[i]);
      }
      // One mesh part over our own buffers; Bullet reads them in place.
      buffer->mesh_interface = std::make_unique<btTriangleIndexVertexArray>(
          mesh->num_triangles(), mesh->indices_.data(), static_cast<int>(3 * sizeof(int32_t)),
          static_cast<int>(x.size()), buffer->positions.data(), static_cast<int>(3 * sizeof(float)));
      buffer->shape = std::make_unique<internal::ShellShape>(buffer->mesh_interface.get());
      buffer->shape->setMargin(static_cast<btScalar>(settings.margin));
    }
    mesh->version_ = 1;
    return mesh;
  });
}

btBvhTriangleMeshShape& CollisionMesh::shape() { return *buffers_[front_]->shape; }
const btBvhTriangleMeshShape& CollisionMesh::shape() const { return *front().shape; }
int32_t CollisionMesh::num_vertices() const { return static_cast<int32_t>(front().positions.size() / 3); }
std::span<const float> CollisionMesh::positions() const { return front().positions; }
const std::vector<Vec3>& CollisionMesh::control_positions() const { return front().control_positions; }

void CollisionMesh::sync() const {
  if (tessellation_stale_) {
    tessellation_.update(front().control_positions);
    tessellation_stale_ = false;
  }
}

const Tessellation& CollisionMesh::tessellation() const {
  sync();
  return tessellation_;
}

std::span<const float> CollisionMesh::normals() const {
  if (normals_stale_) {
    sync();
    const auto& n = tessellation_.normals();
    for (size_t i = 0; i < n.size(); ++i) {
      for (int a = 0; a < 3; ++a) normals_[3 * i + static_cast<size_t>(a)] = static_cast<float>(n[i][a]);
    }
    normals_stale_ = false;
  }
  return normals_;
}

void CollisionMesh::bounds(Vec3& out_min, Vec3& out_max) const {
  out_min = front().lo;
  out_max = front().hi;
}

void CollisionMesh::prepare(std::vector<Vec3> control_positions) {
  prepared_ = false;
  if (control_positions.size() != rest_positions_.size()) {
    fail(ErrorCode::kInvalidArgument, "CollisionMesh::prepare expects " + std::to_string(rest_positions_.size()) +
                                          " control positions, got " + std::to_string(control_positions.size()));
  }
  for (const Vec3& p : control_positions) {
    if (!p.allFinite()) fail(ErrorCode::kInvalidArgument, "CollisionMesh::prepare: non-finite control position");
  }
  Buffer& back = *buffers_[1 - front_];
  back.control_positions = std::move(control_positions);

  // Limit positions: one pass over the rows of S (vertices = S * control points), into floats.
  const auto& S = *limit_;
  const std::vector<Vec3>& cp = back.control_positions;
  Vec3 lo = Vec3::Constant(std::numeric_limits<double>::max()), hi = -lo;
  float* out = back.positions.data();
  for (Eigen::Index row = 0; row < S.outerSize(); ++row, out += 3) {
    Vec3 x = Vec3::Zero();
    for (Eigen::SparseMatrix<double, Eigen::RowMajor>::InnerIterator it(S, row); it; ++it) {
      x += it.value() * cp[static_cast<size_t>(it.col())];
    }
    out[0] = static_cast<float>(x.x());
    out[1] = static_cast<float>(x.y());
    out[2] = static_cast<float>(x.z());
    lo = lo.cwiseMin(x);
    hi = hi.cwiseMax(x);
  }
  back.lo = lo;
  back.hi = hi;

  // Refit: quantize over the new bounds with a margin of 1% of the object's size.
  const auto margin = static_cast<btScalar>(std::max(0.01 * size_, 1e-6));
  back.shape->refit(back.positions.data(), indices_.data(), to_bt(lo), to_bt(hi), margin);
  prepared_ = true;
}

bool CollisionMesh::commit() {
  if (!prepared_) return false;
  front_ = 1 - front_;
  prepared_ = false;
  tessellation_stale_ = true;
  normals_stale_ = true;
  ++version_;
  return true;
}

void CollisionMesh::update(std::vector<Vec3> control_positions) {
  prepare(std::move(control_positions));
  commit();
}

void CollisionMesh::reset() { update(rest_positions_); }

std::array<double, 3> CollisionMesh::barycentric(int32_t triangle, const Vec3& local_point) const {
  if (triangle < 0 || triangle >= num_triangles()) {
    fail(ErrorCode::kInvalidArgument, "triangle index " + std::to_string(triangle) + " is out of range (" +
                                          std::to_string(num_triangles()) + " triangles)");
  }
  const std::vector<float>& x = front().positions;
  const auto corner = [&](int c) {
    const size_t v = static_cast<size_t>(indices_[3 * static_cast<size_t>(triangle) + static_cast<size_t>(c)]);
    return Vec3(x[3 * v], x[3 * v + 1], x[3 * v + 2]);
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
  // Only the quads' topology and parameters are needed: no sync of the tessellation's vertices.
  return tessellation_.surface_point(triangle, barycentric(triangle, local_point));
}

}  // namespace softshell::bullet
