#include "softshell/bullet/collision_mesh.h"

#include <atomic>
#include <random>
#include <thread>

#include <BulletCollision/CollisionShapes/btBvhTriangleMeshShape.h>
#include <btBulletCollisionCommon.h>
#include <gtest/gtest.h>

#include "test_meshes.h"

namespace softshell::bullet {
namespace {

std::unique_ptr<CollisionMesh> make(const ControlMesh& mesh, int level) {
  auto evaluator = LimitEvaluator::create(mesh);
  EXPECT_TRUE(evaluator.ok()) << evaluator.error().message;
  CollisionMeshSettings settings;
  settings.level = level;
  auto out = CollisionMesh::create(*evaluator, settings);
  EXPECT_TRUE(out.ok()) << out.error().message;
  return std::move(*out);
}

// A collision world with one static object over the mesh's shape.
struct RayWorld {
  btDefaultCollisionConfiguration configuration;
  btCollisionDispatcher dispatcher{&configuration};
  btDbvtBroadphase broadphase;
  btCollisionWorld world{&dispatcher, &broadphase, &configuration};
  btCollisionObject object;
  CollisionMesh& mesh;
  explicit RayWorld(CollisionMesh& m) : mesh(m) {
    object.setCollisionShape(&mesh.shape());
    world.addCollisionObject(&object);
  }
  ~RayWorld() { world.removeCollisionObject(&object); }
  // The closest hit and the triangle Bullet reports for it.
  struct Callback : btCollisionWorld::ClosestRayResultCallback {
    using ClosestRayResultCallback::ClosestRayResultCallback;
    int triangle = -1;
    btScalar addSingleResult(btCollisionWorld::LocalRayResult& result, bool normal_in_world) override {
      if (result.m_localShapeInfo) triangle = result.m_localShapeInfo->m_triangleIndex;
      return ClosestRayResultCallback::addSingleResult(result, normal_in_world);
    }
  };
  std::optional<std::pair<Vec3, int32_t>> cast(const Vec3& from, const Vec3& to) {
    object.setCollisionShape(&mesh.shape());  // the visible half of the double buffer
    world.updateSingleAabb(&object);
    const btVector3 a(float(from.x()), float(from.y()), float(from.z())), b(float(to.x()), float(to.y()), float(to.z()));
    Callback hit(a, b);
    world.rayTest(a, b, hit);
    if (!hit.hasHit()) return std::nullopt;
    return std::pair{Vec3(hit.m_hitPointWorld.x(), hit.m_hitPointWorld.y(), hit.m_hitPointWorld.z()), hit.triangle};
  }
};

TEST(CollisionMesh, MirrorsTheTessellation) {
  const ControlMesh mesh = test::make_grid(4, 3);
  for (int level : {0, 1, 3}) {
    auto cm = make(mesh, level);
    const Tessellation& t = cm->tessellation();
    EXPECT_EQ(cm->num_triangles(), 12 * 2 * (1 << (2 * level)));
    ASSERT_EQ(cm->num_triangles(), static_cast<int32_t>(t.triangles().size()));
    ASSERT_EQ(cm->num_vertices(), static_cast<int32_t>(t.vertices().size()));
    for (size_t i = 0; i < t.triangles().size(); ++i) {
      for (size_t c = 0; c < 3; ++c) EXPECT_EQ(cm->indices()[3 * i + c], t.triangles()[i][c]);
    }
    for (size_t i = 0; i < t.vertices().size(); ++i) {
      for (int a = 0; a < 3; ++a) {
        EXPECT_FLOAT_EQ(cm->positions()[3 * i + size_t(a)], float(t.vertices()[i][a]));
        EXPECT_FLOAT_EQ(cm->normals()[3 * i + size_t(a)], float(t.normals()[i][a]));
      }
    }
    EXPECT_EQ(cm->shape().getMeshInterface()->getNumSubParts(), 1);
  }
}

TEST(CollisionMesh, RejectsBadSettings) {
  auto evaluator = LimitEvaluator::create(test::make_grid(2, 2)).value();
  CollisionMeshSettings bad;
  bad.level = 9;
  EXPECT_EQ(CollisionMesh::create(evaluator, bad).error().code, ErrorCode::kInvalidArgument);
  bad.level = 1;
  bad.margin = -1.0;
  EXPECT_EQ(CollisionMesh::create(evaluator, bad).error().code, ErrorCode::kInvalidArgument);
  auto cm = make(test::make_grid(2, 2), 1);
  EXPECT_THROW(cm->barycentric(-1, Vec3::Zero()), Exception);
  EXPECT_THROW(cm->surface_point(cm->num_triangles(), Vec3::Zero()), Exception);
  EXPECT_THROW(cm->update(std::vector<Vec3>(3, Vec3::Zero())), Exception);
}

TEST(CollisionMesh, BarycentricOfPointsOnAndOffTheTriangle) {
  auto cm = make(test::make_grid(2, 2), 1);
  std::mt19937 rng(7);
  std::uniform_real_distribution<double> unit(0.0, 1.0);
  for (int32_t t = 0; t < cm->num_triangles(); ++t) {
    Vec3 corner[3];
    for (int c = 0; c < 3; ++c) {
      const auto v = size_t(cm->indices()[3 * size_t(t) + size_t(c)]);
      corner[c] = Vec3(cm->positions()[3 * v], cm->positions()[3 * v + 1], cm->positions()[3 * v + 2]);
    }
    double a = unit(rng), b = unit(rng);
    if (a + b > 1.0) a = 1.0 - a, b = 1.0 - b;
    const Vec3 inside = (1.0 - a - b) * corner[0] + a * corner[1] + b * corner[2];
    // A point above the triangle projects onto it; the weights are the same.
    const Vec3 n = (corner[1] - corner[0]).cross(corner[2] - corner[0]).normalized();
    const auto w = cm->barycentric(t, inside + 0.01 * n);
    EXPECT_NEAR(w[0], 1.0 - a - b, 1e-5);
    EXPECT_NEAR(w[1], a, 1e-5);
    EXPECT_NEAR(w[2], b, 1e-5);
    // Far outside: clamped to the triangle, weights still in [0, 1] and summing to 1.
    const auto far = cm->barycentric(t, corner[0] + 10.0 * (corner[0] - corner[1]));
    EXPECT_NEAR(far[0] + far[1] + far[2], 1.0, 1e-12);
    for (double x : far) EXPECT_GE(x, 0.0);
  }
}

TEST(CollisionMesh, SurfacePointOfAContactLiesOnTheLimitSurface) {
  // A curved mesh with an extraordinary vertex: the surface point through the quadtree path maps
  // a point of a triangle to the limit surface within the tessellation's chordal error.
  const ControlMesh mesh = test::load_asset_mesh("catmark_helmet.obj");
  auto evaluator = LimitEvaluator::create(mesh).value();
  for (int level : {2, 3}) {
    auto cm = make(mesh, level);
    const double chord = cm->tessellation().chordal_error();
    std::mt19937 rng(3);
    std::uniform_int_distribution<int32_t> pick(0, cm->num_triangles() - 1);
    std::uniform_real_distribution<double> unit(0.0, 1.0);
    for (int k = 0; k < 200; ++k) {
      const int32_t t = pick(rng);
      const auto& tri = cm->tessellation().triangles()[size_t(t)];
      double a = unit(rng), b = unit(rng);
      if (a + b > 1.0) a = 1.0 - a, b = 1.0 - b;
      const auto& x = cm->tessellation().vertices();
      const Vec3 p = (1.0 - a - b) * x[size_t(tri[0])] + a * x[size_t(tri[1])] + b * x[size_t(tri[2])];
      const SurfacePoint sp = cm->surface_point(t, p);
      EXPECT_EQ(sp.face, cm->tessellation().quads()[size_t(t / 2)].root_face);
      EXPECT_LE((evaluator.evaluate(sp).position - p).norm(), 1.5 * chord + 1e-9);
    }
  }
}

TEST(CollisionMesh, UpdateMovesTheShapeRaysSeeAndResetRestores) {
  const ControlMesh mesh = test::make_grid(6, 6);
  auto cm = make(mesh, 2);
  RayWorld rays(*cm);
  const Vec3 from(0.41, 0.52, 1.0), to(0.41, 0.52, -1.0);
  auto hit = rays.cast(from, to);
  ASSERT_TRUE(hit);
  EXPECT_NEAR(hit->first.z(), 0.0, 1e-6);

  // Lift the plate by 0.3 and bulge its middle by 0.5 more: well outside the bounds the BVH was
  // built with, so the refit must re-quantize.
  std::vector<Vec3> moved = mesh.positions();
  for (int j = 0; j <= 6; ++j) {
    for (int i = 0; i <= 6; ++i) {
      const bool inner = i >= 2 && i <= 4 && j >= 2 && j <= 4;
      moved[size_t(test::grid_index(6, i, j))].z() += 0.3 + (inner ? 0.5 : 0.0);
    }
  }
  const uint64_t version = cm->version();
  cm->update(moved);
  EXPECT_GT(cm->version(), version);
  hit = rays.cast(from, to);
  ASSERT_TRUE(hit);
  Vec3 lo, hi;
  cm->bounds(lo, hi);
  EXPECT_GT(hi.z(), 0.5);
  EXPECT_GT(hit->first.z(), 0.3);
  // The hit triangle's surface point is on the moved limit surface (within the chordal error of
  // the moved shape, here bounded by the bulge's curvature at level 2).
  auto evaluator = LimitEvaluator::create(mesh).value();
  ASSERT_GE(hit->second, 0);
  const SurfacePoint sp = cm->surface_point(hit->second, hit->first);
  EXPECT_LT((evaluator.evaluate(sp, moved).position - hit->first).norm(), 5e-3);

  cm->reset();
  hit = rays.cast(from, to);
  ASSERT_TRUE(hit);
  EXPECT_NEAR(hit->first.z(), 0.0, 1e-6);
}

TEST(CollisionMesh, PrepareOnAThreadWhileBulletUsesTheVisibleShape) {
  const ControlMesh mesh = test::make_grid(8, 8);
  auto cm = make(mesh, 3);
  RayWorld rays(*cm);
  const Vec3 from(0.3, 0.6, 1.0), to(0.3, 0.6, -1.0);
  EXPECT_FALSE(cm->commit());  // nothing prepared
  const btBvhTriangleMeshShape* before = &cm->shape();
  const uint64_t version = cm->version();

  // Raise the plate by 0.25 on another thread while rays keep hitting the visible (rest) shape.
  std::vector<Vec3> raised = mesh.positions();
  for (Vec3& p : raised) p.z() += 0.25;
  std::atomic<bool> done{false};
  std::thread worker([&] {
    cm->prepare(raised);
    done = true;
  });
  int casts = 0;
  while (!done || casts < 10) {
    btCollisionWorld::ClosestRayResultCallback hit(btVector3(0.3f, 0.6f, 1.0f), btVector3(0.3f, 0.6f, -1.0f));
    rays.world.rayTest(hit.m_rayFromWorld, hit.m_rayToWorld, hit);
    ASSERT_TRUE(hit.hasHit());
    EXPECT_NEAR(hit.m_hitPointWorld.z(), 0.0, 1e-6);
    ++casts;
  }
  worker.join();
  EXPECT_TRUE(cm->prepared());
  EXPECT_EQ(&cm->shape(), before);
  EXPECT_EQ(cm->version(), version);
  EXPECT_EQ(cm->control_positions(), mesh.positions());

  ASSERT_TRUE(cm->commit());
  EXPECT_FALSE(cm->prepared());
  EXPECT_NE(&cm->shape(), before);
  EXPECT_EQ(cm->version(), version + 1);
  EXPECT_EQ(cm->control_positions(), raised);
  auto hit = rays.cast(from, to);
  ASSERT_TRUE(hit);
  EXPECT_NEAR(hit->first.z(), 0.25, 1e-6);
  // Rendering data and the tessellation follow the committed shape.
  EXPECT_NEAR(cm->positions()[2], 0.25f, 1e-6f);
  EXPECT_NEAR(cm->tessellation().vertices()[0].z(), 0.25, 1e-12);
  EXPECT_NEAR(cm->normals()[2], 1.0f, 1e-6f);
  Vec3 lo, hi;
  cm->bounds(lo, hi);
  EXPECT_NEAR(lo.z(), 0.25, 1e-12);

  // A failed prepare leaves nothing prepared and the visible shape alone.
  EXPECT_THROW(cm->prepare(std::vector<Vec3>(3, Vec3::Zero())), Exception);
  std::vector<Vec3> bad = raised;
  bad[5].x() = std::nan("");
  EXPECT_THROW(cm->prepare(bad), Exception);
  EXPECT_FALSE(cm->commit());
  EXPECT_EQ(cm->control_positions(), raised);
}

}  // namespace
}  // namespace softshell::bullet
