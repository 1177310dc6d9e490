#include "softshell/limit_evaluator.h"

#include <random>

#include <gtest/gtest.h>

#include "test_meshes.h"

namespace softshell {
namespace {

double sum(const std::vector<double>& w) {
  double s = 0.0;
  for (double x : w) s += x;
  return s;
}

// Uniform cubic B-spline basis and derivatives, written out independently of OpenSubdiv.
void bspline(double t, double b[4], double d[4], double dd[4]) {
  const double s = 1.0 - t;
  b[0] = s * s * s / 6.0;
  b[1] = (3 * t * t * t - 6 * t * t + 4) / 6.0;
  b[2] = (-3 * t * t * t + 3 * t * t + 3 * t + 1) / 6.0;
  b[3] = t * t * t / 6.0;
  d[0] = -s * s / 2.0;
  d[1] = (9 * t * t - 12 * t) / 6.0;
  d[2] = (-9 * t * t + 6 * t + 3) / 6.0;
  d[3] = t * t / 2.0;
  dd[0] = s;
  dd[1] = 3 * t - 2;
  dd[2] = -3 * t + 1;
  dd[3] = t;
}

TEST(LimitEvaluator, WeightsArePartitionOfUnityOnEveryMesh) {
  std::mt19937 rng(7);
  std::uniform_real_distribution<double> uni(0.0, 1.0);
  for (const auto& name : test::asset_mesh_names()) {
    ControlMesh mesh = test::load_asset_mesh(name);
    auto ev = LimitEvaluator::create(mesh);
    ASSERT_TRUE(ev.ok()) << name << ": " << ev.error().message;
    // Every face on the small meshes, a sample of faces on the large ones.
    const int32_t step = std::max(1, mesh.num_faces() / 300);
    for (int32_t f = 0; f < mesh.num_faces(); f += step) {
      for (int32_t s = 0; s < ev->num_subfaces(f); ++s) {
        SurfacePoint p{f, s, uni(rng), uni(rng)};
        LimitStencil st = ev->stencil(p);
        ASSERT_GT(st.size(), 0u);
        EXPECT_NEAR(sum(st.position), 1.0, 1e-12) << name << " face " << f;
        for (const auto* w : {&st.du, &st.dv, &st.duu, &st.duv, &st.dvv}) {
          EXPECT_NEAR(sum(*w), 0.0, 1e-9) << name << " face " << f;
        }
      }
    }
  }
}

TEST(LimitEvaluator, RegularPatchEqualsBicubicBSpline) {
  std::mt19937 rng(3);
  std::uniform_real_distribution<double> uni(-0.3, 0.3);
  const int n = 5;
  ControlMesh mesh = test::make_grid(n, n, 1.0, 1.0, [&](double, double) { return uni(rng); });
  for (Vec3& p : mesh.positions()) p += Vec3(0.1 * uni(rng), 0.1 * uni(rng), 0.0);  // not a plain grid
  auto ev = LimitEvaluator::create(mesh).value();
  const int fi = 2, fj = 2;  // interior face: its 4x4 neighbourhood is all interior
  const int32_t face = fj * n + fi;
  ASSERT_TRUE(ev.is_regular(face));
  for (double u : {0.0, 0.13, 0.5, 0.77, 1.0}) {
    for (double v : {0.0, 0.31, 0.5, 0.92, 1.0}) {
      LimitStencil st = ev.stencil({face, 0, u, v});
      double bu[4], du[4], ddu[4], bv[4], dv[4], ddv[4];
      bspline(u, bu, du, ddu);
      bspline(v, bv, dv, ddv);
      // Expected weights of control point (fi - 1 + a, fj - 1 + b).
      for (size_t k = 0; k < st.size(); ++k) {
        const int idx = st.indices[k];
        const int a = idx % (n + 1) - (fi - 1), b = idx / (n + 1) - (fj - 1);
        ASSERT_TRUE(a >= 0 && a < 4 && b >= 0 && b < 4) << "control point " << idx << " outside the patch";
        EXPECT_NEAR(st.position[k], bu[a] * bv[b], 1e-13);
        EXPECT_NEAR(st.du[k], du[a] * bv[b], 1e-12);
        EXPECT_NEAR(st.dv[k], bu[a] * dv[b], 1e-12);
        EXPECT_NEAR(st.duu[k], ddu[a] * bv[b], 1e-11);
        EXPECT_NEAR(st.duv[k], du[a] * dv[b], 1e-11);
        EXPECT_NEAR(st.dvv[k], bu[a] * ddv[b], 1e-11);
      }
      // 16 control points, or fewer where a weight vanishes identically.
      EXPECT_LE(st.size(), 16u);
    }
  }
}

TEST(LimitEvaluator, FlatMeshStaysFlat) {
  std::mt19937 rng(11);
  std::uniform_real_distribution<double> uni(-0.2, 0.2);
  ControlMesh mesh = test::make_grid(6, 4, 3.0, 2.0);
  for (Vec3& p : mesh.positions()) p += Vec3(uni(rng), uni(rng), 0.0);
  auto ev = LimitEvaluator::create(mesh).value();
  std::uniform_real_distribution<double> param(0.0, 1.0);
  for (int32_t f = 0; f < mesh.num_faces(); ++f) {
    LimitSample s = ev.evaluate({f, 0, param(rng), param(rng)});
    EXPECT_NEAR(s.position.z(), 0.0, 1e-14);
    EXPECT_NEAR(s.du.z(), 0.0, 1e-13);
    EXPECT_NEAR(s.duv.z(), 0.0, 1e-12);
    EXPECT_NEAR(std::abs(s.normal().z()), 1.0, 1e-12);
  }
}

// Points on a shared edge seen from both faces: same position and same tangent plane.
TEST(LimitEvaluator, ContinuousAcrossSharedEdges) {
  for (const auto& name : test::small_asset_mesh_names(800)) {
    ControlMesh mesh = test::load_asset_mesh(name);
    if (mesh.has_sharpness()) continue;  // creases are C0 by design
    auto ev = LimitEvaluator::create(mesh).value();
    // Map every quad edge (a, b) to the faces that use it.
    std::map<std::pair<int, int>, std::vector<std::pair<int, int>>> edges;  // -> (face, local edge)
    for (int32_t f = 0; f < mesh.num_faces(); ++f) {
      if (mesh.face_size(f) != 4) continue;
      auto fv = mesh.face(f);
      for (int e = 0; e < 4; ++e) edges[{std::min(fv[e], fv[(e + 1) % 4]), std::max(fv[e], fv[(e + 1) % 4])}].push_back({f, e});
    }
    // Point at parameter t along local edge e of a quad, going from corner e to corner e+1.
    auto edge_point = [](int face, int e, double t) {
      switch (e) {
        case 0: return SurfacePoint{face, 0, t, 0.0};
        case 1: return SurfacePoint{face, 0, 1.0, t};
        case 2: return SurfacePoint{face, 0, 1.0 - t, 1.0};
        default: return SurfacePoint{face, 0, 0.0, 1.0 - t};
      }
    };
    const double size = mesh.bounding_diagonal();
    int checked = 0;
    for (const auto& [key, uses] : edges) {
      if (uses.size() != 2) continue;
      for (double t : {0.25, 0.5, 0.8}) {
        // The second face runs along the edge the other way.
        LimitSample a = ev.evaluate(edge_point(uses[0].first, uses[0].second, t));
        LimitSample b = ev.evaluate(edge_point(uses[1].first, uses[1].second, 1.0 - t));
        EXPECT_LT((a.position - b.position).norm(), 1e-12 * size) << name;
        EXPECT_GT(std::abs(a.normal().dot(b.normal())), 1.0 - 1e-9) << name << " faces " << uses[0].first << ", "
                                                                      << uses[1].first;
        ++checked;
      }
    }
    EXPECT_GT(checked, 0) << name;
  }
}

// The derivative weights are derivatives of the position weights (also for n-gon sub-faces,
// where Bfr's coordinates must be rescaled to the protocol's normalized ones).
TEST(LimitEvaluator, DerivativesMatchFiniteDifferences) {
  for (const char* name : {"catmark_nonquads.obj", "catmark_gregory_test5.obj", "catmark_cube.obj"}) {
    ControlMesh mesh = test::load_asset_mesh(name);
    auto ev = LimitEvaluator::create(mesh).value();
    const double h = 1e-6;
    for (int32_t f = 0; f < mesh.num_faces(); ++f) {
      for (int32_t s = 0; s < ev.num_subfaces(f); ++s) {
        const double u = 0.4, v = 0.6;
        LimitSample c = ev.evaluate({f, s, u, v});
        LimitSample pu = ev.evaluate({f, s, u + h, v}), mu = ev.evaluate({f, s, u - h, v});
        LimitSample pv = ev.evaluate({f, s, u, v + h}), mv = ev.evaluate({f, s, u, v - h});
        const double scale = c.du.norm() + c.dv.norm();
        EXPECT_LT(((pu.position - mu.position) / (2 * h) - c.du).norm(), 1e-6 * scale) << name << " " << f << "/" << s;
        EXPECT_LT(((pv.position - mv.position) / (2 * h) - c.dv).norm(), 1e-6 * scale) << name << " " << f << "/" << s;
        EXPECT_LT(((pu.du - mu.du) / (2 * h) - c.duu).norm(), 1e-4 * scale) << name << " " << f << "/" << s;
        EXPECT_LT(((pv.du - mv.du) / (2 * h) - c.duv).norm(), 1e-4 * scale) << name << " " << f << "/" << s;
        EXPECT_LT(((pv.dv - mv.dv) / (2 * h) - c.dvv).norm(), 1e-4 * scale) << name << " " << f << "/" << s;
      }
    }
  }
}

// Sub-face k of an n-gon has (0,0) at corner k, (1,0) at the midpoint of edge k -> k+1 and (1,1)
// at the face centre: neighbouring sub-faces meet along their shared half edges.
TEST(LimitEvaluator, NgonSubfacesFollowTheProtocolConvention) {
  ControlMesh mesh = test::load_asset_mesh("catmark_nonquads.obj");
  auto ev = LimitEvaluator::create(mesh).value();
  int ngons = 0;
  for (int32_t f = 0; f < mesh.num_faces(); ++f) {
    const int32_t n = mesh.face_size(f);
    if (n == 4) continue;
    ++ngons;
    ASSERT_EQ(ev.num_subfaces(f), n);
    const Vec3 centre = ev.evaluate({f, 0, 1.0, 1.0}).position;
    for (int32_t k = 0; k < n; ++k) {
      EXPECT_LT((ev.evaluate({f, k, 1.0, 1.0}).position - centre).norm(), 1e-12);
      // (1, t) of sub-face k is (t, 1) of sub-face k+1 (the half edge from edge k's midpoint to the centre).
      for (double t : {0.3, 0.7}) {
        Vec3 a = ev.evaluate({f, k, 1.0, t}).position;
        Vec3 b = ev.evaluate({f, (k + 1) % n, t, 1.0}).position;
        EXPECT_LT((a - b).norm(), 1e-12) << "face " << f << " sub-face " << k;
      }
    }
  }
  EXPECT_GT(ngons, 0);
}

TEST(LimitEvaluator, RejectsBadPointsWithAReason) {
  auto ev = LimitEvaluator::create(test::load_asset_mesh("catmark_nonquads.obj")).value();
  EXPECT_NE(ev.check({-1, 0, 0.5, 0.5}).error().message.find("out of range"), std::string::npos);
  EXPECT_NE(ev.check({ev.num_faces(), 0, 0.5, 0.5}).error().message.find("out of range"), std::string::npos);
  EXPECT_FALSE(ev.check({0, 0, 1.5, 0.5}).ok());
  EXPECT_FALSE(ev.check({0, 0, std::nan(""), 0.5}).ok());
  EXPECT_FALSE(ev.check({0, 7, 0.5, 0.5}).ok());
  EXPECT_THROW((void)ev.stencil({0, 0, -0.1, 0.5}), Exception);
  EXPECT_TRUE(ev.check({0, 0, 1.0, 0.0}).ok());
}

TEST(LimitEvaluator, RejectsInvalidMeshes) {
  ControlMesh mesh({Vec3(0, 0, 0), Vec3(1, 0, 0), Vec3(1, 1, 0)}, std::vector<std::vector<int32_t>>{{0, 1, 5}});
  auto ev = LimitEvaluator::create(mesh);
  ASSERT_FALSE(ev.ok());
  EXPECT_EQ(ev.error().code, ErrorCode::kInvalidArgument);
}

TEST(LimitEvaluator, BoundaryNoneMakesGhostFaces) {
  ControlMesh mesh = test::make_grid(5, 5);
  mesh.set_boundary(BoundaryMode::kNone);
  auto ev = LimitEvaluator::create(mesh).value();
  int with_surface = 0;
  for (int32_t f = 0; f < mesh.num_faces(); ++f) with_surface += ev.has_limit_surface(f);
  EXPECT_EQ(with_surface, 9);  // the 3x3 interior faces
  EXPECT_FALSE(ev.check({0, 0, 0.5, 0.5}).ok());
  EXPECT_NE(ev.check({0, 0, 0.5, 0.5}).error().message.find("ghost"), std::string::npos);
}

TEST(LimitEvaluator, FaceStencilsMatchSingleStencils) {
  ControlMesh mesh = test::load_asset_mesh("catmark_cube.obj");
  auto ev = LimitEvaluator::create(mesh).value();
  std::vector<std::array<double, 2>> uvs = {{0.1, 0.2}, {0.9, 0.5}};
  std::vector<int32_t> indices;
  Eigen::MatrixXd w;
  ev.face_stencils(2, 0, uvs, indices, w);
  ASSERT_EQ(w.rows(), 12);
  for (size_t i = 0; i < uvs.size(); ++i) {
    LimitStencil st = ev.stencil({2, 0, uvs[i][0], uvs[i][1]});
    for (size_t k = 0; k < st.size(); ++k) {
      const auto col = std::find(indices.begin(), indices.end(), st.indices[k]) - indices.begin();
      ASSERT_LT(col, static_cast<long>(indices.size()));
      EXPECT_NEAR(w(static_cast<long>(6 * i), col), st.position[k], 1e-15);
      EXPECT_NEAR(w(static_cast<long>(6 * i + 4), col), st.duv[k], 1e-13);
    }
  }
}

}  // namespace
}  // namespace softshell
