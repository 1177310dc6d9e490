#include "softshell/tessellation.h"

#include <random>

#include <gtest/gtest.h>

#include "test_meshes.h"

namespace softshell {
namespace {

TEST(QuadtreePath, PaperExample) {
  // Paper Section 5.1: path [2, 1] covers u in [0.75, 1], v in [0.5, 0.75].
  QuadtreePath path = QuadtreePath::from_corners({2, 1});
  EXPECT_EQ(path.depth, 2);
  EXPECT_EQ(path.corner(0), 2);
  EXPECT_EQ(path.corner(1), 1);
  EXPECT_EQ(path.range(), (ParamRect{0.75, 0.5, 1.0, 0.75}));
  EXPECT_EQ(QuadtreePath{}.range(), (ParamRect{0.0, 0.0, 1.0, 1.0}));
  EXPECT_EQ(QuadtreePath::from_corners({3}).range(), (ParamRect{0.0, 0.5, 0.5, 1.0}));
  EXPECT_THROW(QuadtreePath::from_corners({4}), Exception);
}

TEST(Tessellation, CountsAndPathsOfARegularGrid) {
  ControlMesh mesh = test::make_grid(3, 2);
  auto ev = LimitEvaluator::create(mesh).value();
  for (int level = 0; level <= 4; ++level) {
    auto t = Tessellation::create(ev, level).value();
    const size_t per_face = size_t{1} << (2 * level);
    ASSERT_EQ(t.quads().size(), 6 * per_face);
    EXPECT_EQ(t.triangles().size(), 2 * t.quads().size());
    EXPECT_EQ(t.vertices().size(), static_cast<size_t>((3 * (1 << level) + 1) * (2 * (1 << level) + 1)));
    // Every face is tiled exactly once by the paths of its quads.
    std::vector<std::set<uint64_t>> paths(6);
    for (const auto& q : t.quads()) {
      EXPECT_EQ(q.path.depth, level);
      EXPECT_TRUE(paths[static_cast<size_t>(q.root_face)].insert(q.path.bits).second);
    }
    for (const auto& p : paths) EXPECT_EQ(p.size(), per_face);
  }
}

// The strongest check of root face, path and rotation: the limit surface evaluated at each quad
// corner's parameters is exactly the tessellation vertex there.
TEST(Tessellation, QuadCornerParamsReproduceVertices) {
  for (const auto& name : test::small_asset_mesh_names(800)) {
    ControlMesh mesh = test::load_asset_mesh(name);
    auto ev = LimitEvaluator::create(mesh).value();
    auto t = Tessellation::create(ev, 2).value();
    const double size = mesh.bounding_diagonal();
    for (int32_t q = 0; q < static_cast<int32_t>(t.quads().size()); ++q) {
      const auto& quad = t.quads()[static_cast<size_t>(q)];
      const auto params = t.quad_corner_params(q);
      for (int c = 0; c < 4; ++c) {
        Vec3 p = ev.evaluate({quad.root_face, quad.subface, params[static_cast<size_t>(c)][0],
                              params[static_cast<size_t>(c)][1]}).position;
        ASSERT_LT((p - t.vertices()[static_cast<size_t>(quad.vertices[static_cast<size_t>(c)])]).norm(), 1e-12 * size)
            << name << " quad " << q << " corner " << c;
      }
    }
  }
}

TEST(Tessellation, PointsMapBackWithinTheChordalError) {
  std::mt19937 rng(5);
  std::uniform_real_distribution<double> uni(0.0, 1.0);
  for (const char* name : {"catmark_torus.obj", "catmark_nonquads.obj", "catmark_helmet.obj", "blub_control_mesh.obj"}) {
    ControlMesh mesh = test::load_asset_mesh(name);
    auto ev = LimitEvaluator::create(mesh).value();
    bool smooth_parameterization = !mesh.has_sharpness();
    for (int32_t f = 0; f < mesh.num_faces(); ++f) smooth_parameterization &= ev.is_regular(f);
    double previous = std::numeric_limits<double>::infinity();
    for (int level = 1; level <= 4; ++level) {
      auto t = Tessellation::create(ev, level).value();
      const double chordal = t.chordal_error();
      double worst = 0.0;
      for (int i = 0; i < 2000; ++i) {
        const auto tri = static_cast<int32_t>(rng() % t.triangles().size());
        double a = uni(rng), b = uni(rng);
        if (a + b > 1.0) { a = 1.0 - a; b = 1.0 - b; }
        const std::array<double, 3> bary{1.0 - a - b, a, b};
        const auto& corners = t.triangles()[static_cast<size_t>(tri)];
        Vec3 on_triangle = Vec3::Zero();
        for (int c = 0; c < 3; ++c) on_triangle += bary[static_cast<size_t>(c)] * t.vertices()[static_cast<size_t>(corners[static_cast<size_t>(c)])];
        const SurfacePoint p = t.surface_point(tri, bary);
        ASSERT_TRUE(ev.check(p).ok());
        worst = std::max(worst, (ev.evaluate(p).position - on_triangle).norm());
      }
      // The chordal error is a maximum over a 28-point grid per triangle; random points may
      // exceed it only by the grid's sampling error.
      EXPECT_LE(worst, 1.05 * chordal) << name << " level " << level;
      EXPECT_GT(worst, 0.2 * chordal) << name << " level " << level;
      // Away from extraordinary vertices and creases each level quarters the error (second
      // order; require a factor 3). Near them the Catmull-Clark parameterization is not smooth
      // (the limit surface is C1 but not a regular C2 map of (u, v)), so the error still shrinks
      // with every level, only more slowly.
      EXPECT_LT(chordal, (smooth_parameterization ? 1.0 / 3.0 : 1.0) * previous) << name << " level " << level;
      previous = chordal;
    }
  }
}

TEST(Tessellation, NormalsPointOutwardOnClosedMeshes) {
  for (const char* name : {"catmark_cube.obj", "spot_control_mesh.obj", "catmark_torus.obj"}) {
    auto ev = LimitEvaluator::create(test::load_asset_mesh(name)).value();
    auto t = Tessellation::create(ev, 2).value();
    // Signed volume of the closed triangle mesh is positive, and vertex normals agree with faces.
    double volume = 0.0;
    for (const auto& tri : t.triangles()) {
      const Vec3 &a = t.vertices()[static_cast<size_t>(tri[0])], &b = t.vertices()[static_cast<size_t>(tri[1])],
                 &c = t.vertices()[static_cast<size_t>(tri[2])];
      volume += a.dot(b.cross(c)) / 6.0;
      const Vec3 face_normal = (b - a).cross(c - a);
      EXPECT_GT(face_normal.dot(t.normals()[static_cast<size_t>(tri[0])]), 0.0) << name;
    }
    EXPECT_GT(volume, 0.0) << name;
  }
}

TEST(Tessellation, UpdateFollowsDeformedControlPoints) {
  ControlMesh mesh = test::load_asset_mesh("catmark_gregory_test5.obj");
  auto ev = LimitEvaluator::create(mesh).value();
  auto t = Tessellation::create(ev, 3).value();
  const std::vector<Vec3> rest = t.vertices();
  // A translation moves every limit point by the same vector.
  std::vector<Vec3> moved = mesh.positions();
  for (Vec3& p : moved) p += Vec3(0.5, -1.0, 2.0);
  t.update(moved);
  for (size_t i = 0; i < rest.size(); ++i) EXPECT_LT((t.vertices()[i] - rest[i] - Vec3(0.5, -1.0, 2.0)).norm(), 1e-12);
  // A general deformation matches direct evaluation.
  for (size_t i = 0; i < moved.size(); ++i) moved[i] = mesh.positions()[i] + Vec3(0.0, 0.0, 0.1 * double(i % 3));
  t.update(moved);
  for (size_t i = 0; i < rest.size(); i += 7) {
    LimitSample s = ev.evaluate(t.vertex_points()[i], moved);
    EXPECT_LT((t.vertices()[i] - s.position).norm(), 1e-12);
    EXPECT_GT(t.normals()[i].dot(s.normal()), 1.0 - 1e-12);
  }
  EXPECT_THROW(t.update({Vec3::Zero()}), Exception);
}

TEST(Tessellation, RejectsBadLevelsAndHugeResults) {
  auto ev = LimitEvaluator::create(test::load_asset_mesh("catmark_nonquads.obj")).value();
  EXPECT_EQ(Tessellation::create(ev, -1).error().code, ErrorCode::kInvalidArgument);
  EXPECT_EQ(Tessellation::create(ev, 9).error().code, ErrorCode::kInvalidArgument);
  EXPECT_EQ(Tessellation::create(ev, 0).error().code, ErrorCode::kInvalidArgument);  // n-gons need level >= 1
  EXPECT_EQ(Tessellation::create(ev, 6, 1000).error().code, ErrorCode::kResourceExhausted);
  auto t = Tessellation::create(ev, 1).value();
  EXPECT_THROW((void)t.surface_point(-1, {1, 0, 0}), Exception);
}

TEST(Tessellation, NgonFacesStartWithSubfaces) {
  ControlMesh mesh = test::load_asset_mesh("catmark_nonquads.obj");
  auto ev = LimitEvaluator::create(mesh).value();
  auto t = Tessellation::create(ev, 1).value();
  for (const auto& q : t.quads()) {
    if (mesh.face_size(q.root_face) == 4) {
      EXPECT_EQ(q.path.depth, 1);
      EXPECT_EQ(q.subface, 0);
    } else {
      EXPECT_EQ(q.path.depth, 0);
      EXPECT_LT(q.subface, mesh.face_size(q.root_face));
    }
  }
}

}  // namespace
}  // namespace softshell
