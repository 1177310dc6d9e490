#include "softshell/limit_evaluator.h"

#include <algorithm>
#include <map>
#include <memory>
#include <random>

#include <gtest/gtest.h>
#include <opensubdiv/bfr/refinerSurfaceFactory.h>
#include <opensubdiv/far/primvarRefiner.h>
#include <opensubdiv/far/topologyDescriptor.h>

#include "shell_benchmarks.h"
#include "test_meshes.h"

namespace softshell {
namespace {

namespace Bfr = OpenSubdiv::Bfr;
namespace Far = OpenSubdiv::Far;

// A point for Far::PrimvarRefiner.
struct Point3 {
  Vec3 v = Vec3::Zero();
  Point3() = default;
  Point3(const Vec3& x) : v(x) {}  // NOLINT(google-explicit-constructor)
  void Clear() { v.setZero(); }
  void AddWithWeight(const Point3& src, double weight) { v += weight * src.v; }
};

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

// ---------------------------------------------------------------------------------------------
// Exact evaluation at extraordinary vertices, against OpenSubdiv where OpenSubdiv is exact.

// OpenSubdiv's own objects for a mesh (the same options as the evaluator's).
struct Osd {
  std::unique_ptr<Far::TopologyRefiner> refiner;
  explicit Osd(const ControlMesh& mesh) {
    const std::vector<int32_t> sizes = mesh.face_sizes();
    Far::TopologyDescriptor desc;
    desc.numVertices = mesh.num_vertices();
    desc.numFaces = mesh.num_faces();
    desc.numVertsPerFace = sizes.data();
    desc.vertIndicesPerFace = mesh.face_indices().data();
    OpenSubdiv::Sdc::Options sdc;
    sdc.SetVtxBoundaryInterpolation(mesh.boundary() == BoundaryMode::kNone
                                        ? OpenSubdiv::Sdc::Options::VTX_BOUNDARY_NONE
                                        : OpenSubdiv::Sdc::Options::VTX_BOUNDARY_EDGE_AND_CORNER);
    refiner.reset(Far::TopologyRefinerFactory<Far::TopologyDescriptor>::Create(
        desc, Far::TopologyRefinerFactory<Far::TopologyDescriptor>::Options(OpenSubdiv::Sdc::SCHEME_CATMARK, sdc)));
  }
};

// The meshes with extraordinary vertices: inside and on the boundary, n-gons, a ghost layer.
std::vector<std::pair<std::string, ControlMesh>> ev_meshes() {
  std::vector<std::pair<std::string, ControlMesh>> out;
  for (const char* name : {"catmark_nonquads.obj", "catmark_gregory_test5.obj", "catmark_cube.obj", "spot_control_mesh.obj",
                           "blub_control_mesh.obj"}) {
    ControlMesh mesh = test::load_asset_mesh(name);
    mesh.creases().clear();
    mesh.corners().clear();
    out.emplace_back(name, mesh);
  }
  out.emplace_back("fan of valence 7", test::fan_plate(7, 3));
  out.emplace_back("fan of valence 12", test::fan_plate(12, 2));
  out.emplace_back("boundary fan of 5 faces", test::fan_plate(6, 2, 5));
  out.emplace_back("boundary fan of 8 faces", test::fan_plate(10, 2, 8));
  ControlMesh ghost = test::make_ev_plate(8, 1.0).mesh;
  ghost.set_boundary(BoundaryMode::kNone);
  out.emplace_back("plate with a ghost layer", ghost);
  for (auto& [name, mesh] : out) {
    std::mt19937 rng(5);
    std::uniform_real_distribution<double> uni(-0.1, 0.1);
    for (Vec3& p : mesh.positions()) p += Vec3(uni(rng), uni(rng), uni(rng));  // generic geometry
  }
  return out;
}

// Where Bfr's patch tree consists of exact B-spline patches (away from the extraordinary
// corners, which it approximates within 2^-6 or so), the exact evaluation must be the same.
TEST(LimitEvaluator, ExactEvaluationAgreesWithBfrWhereBfrIsExact) {
  std::mt19937 rng(17);
  for (const auto& [name, mesh] : ev_meshes()) {
    auto ev = LimitEvaluator::create(mesh).value();
    Osd osd(mesh);
    Bfr::SurfaceFactory::Options options;
    options.SetApproxLevelSmooth(10);
    Bfr::RefinerSurfaceFactory<> factory(*osd.refiner, options);
    const double size = mesh.bounding_diagonal();
    int checked = 0;
    for (int32_t f = 0; f < mesh.num_faces(); ++f) {
      if (!ev.has_limit_surface(f) || ev.is_regular(f)) continue;  // regular faces are Bfr themselves
      Bfr::Surface<double> surface;
      ASSERT_TRUE(factory.InitVertexSurface(f, &surface));
      std::vector<double> patch(3 * static_cast<size_t>(surface.GetNumPatchPoints()));
      const Bfr::Surface<double>::PointDescriptor desc(3);
      surface.PreparePatchPoints(mesh.positions().front().data(), desc, patch.data(), desc);
      const Bfr::Parameterization param = surface.GetParameterization();
      double scale = 1.0;  // Bfr's sub-face coordinates are scaled
      if (param.HasSubFaces()) {
        const double a[2] = {0.0, 0.0}, b[2] = {1.0, 0.0};
        double ua[2], ub[2];
        param.ConvertNormalizedSubFaceToCoord(0, a, ua);
        param.ConvertNormalizedSubFaceToCoord(0, b, ub);
        scale = ub[0] - ua[0];
      }
      std::uniform_real_distribution<double> uni(0.05, 0.95);
      for (int32_t s = 0; s < ev.num_subfaces(f); ++s) {
        for (int k = 0; k < 6; ++k) {
          const double uv[2] = {uni(rng), uni(rng)};
          double bfr_uv[2] = {uv[0], uv[1]};
          if (param.HasSubFaces()) param.ConvertNormalizedSubFaceToCoord(s, uv, bfr_uv);
          double p[3], du[3], dv[3], duu[3], duv[3], dvv[3];
          surface.Evaluate(bfr_uv, patch.data(), desc, p, du, dv, duu, duv, dvv);
          const LimitSample x = ev.evaluate({f, s, uv[0], uv[1]});
          EXPECT_LT((x.position - Vec3(p[0], p[1], p[2])).norm(), 1e-12 * size) << name << " face " << f;
          EXPECT_LT((x.du - scale * Vec3(du[0], du[1], du[2])).norm(), 1e-11 * size) << name << " face " << f;
          EXPECT_LT((x.dv - scale * Vec3(dv[0], dv[1], dv[2])).norm(), 1e-11 * size) << name << " face " << f;
          EXPECT_LT((x.duv - scale * scale * Vec3(duv[0], duv[1], duv[2])).norm(), 1e-10 * size) << name << " face " << f;
          ++checked;
        }
      }
    }
    EXPECT_GT(checked, 0) << name;
  }
}

// At every control point the limit position is Far::PrimvarRefiner's limit (OpenSubdiv's limit
// masks, exact at extraordinary vertices too; taken after one refinement, as Far's Catmull-Clark
// masks assume quads around the vertex).
TEST(LimitEvaluator, LimitPositionsAtVerticesAreOpenSubdivsLimit) {
  for (const auto& [name, mesh] : ev_meshes()) {
    if (mesh.boundary() == BoundaryMode::kNone) continue;  // Far has no limit for the ghost layer's points
    auto ev = LimitEvaluator::create(mesh).value();
    Osd osd(mesh);
    Far::TopologyRefiner::UniformOptions uniform(1);
    uniform.fullTopologyInLastLevel = true;
    osd.refiner->RefineUniform(uniform);
    std::vector<Point3> src(mesh.positions().begin(), mesh.positions().end());
    std::vector<Point3> level1(static_cast<size_t>(osd.refiner->GetLevel(1).GetNumVertices())), limit(level1.size());
    Far::PrimvarRefinerReal<double> primvar(*osd.refiner);
    primvar.Interpolate(1, src, level1);
    primvar.Limit(level1, limit);
    const double size = mesh.bounding_diagonal();
    for (int32_t f = 0; f < mesh.num_faces(); ++f) {
      auto fv = mesh.face(f);
      for (size_t c = 0; c < fv.size(); ++c) {
        // Corner c: (0, 0) of sub-face c of an n-gon; corner c of a quad.
        static constexpr double kCorner[4][2] = {{0, 0}, {1, 0}, {1, 1}, {0, 1}};
        const SurfacePoint p = fv.size() == 4 ? SurfacePoint{f, 0, kCorner[c][0], kCorner[c][1]}
                                              : SurfacePoint{f, static_cast<int32_t>(c), 0.0, 0.0};
        const Vec3 x = ev.evaluate(p).position;
        const auto child = static_cast<size_t>(osd.refiner->GetLevel(0).GetVertexChildVertex(fv[c]));
        EXPECT_LT((x - limit[child].v).norm(), 1e-12 * size) << name << " vertex " << fv[c];
      }
    }
  }
}

// The derivative weights are the derivatives of the position weights, arbitrarily close to an
// extraordinary vertex: five-point differences (exact for the cubics inside one ring's patch)
// at points 2^-n from the vertex.
TEST(LimitEvaluator, DerivativeWeightsAreDerivativesOfPositionWeightsNearExtraordinaryVertices) {
  auto weights_at = [](const LimitEvaluator& ev, SurfacePoint p, int which) {
    const LimitStencil st = ev.stencil(p);
    const std::vector<double>* rows[6] = {&st.position, &st.du, &st.dv, &st.duu, &st.duv, &st.dvv};
    return Eigen::Map<const Eigen::VectorXd>(rows[which]->data(), static_cast<Eigen::Index>(rows[which]->size())).eval();
  };
  int checked = 0;
  for (const auto& [name, mesh] : ev_meshes()) {
    auto ev = LimitEvaluator::create(mesh).value();
    std::vector<double> factors;
    for (int32_t f = 0; f < mesh.num_faces(); ++f) {
      for (int32_t s = 0; s < ev.num_subfaces(f); ++s) {
        for (int corner = 0; corner < 4; ++corner) {
          if (!ev.ev_corner_weights(f, s, corner, 0.25, 2, factors)) continue;  // not an EV corner
          const double cu = (corner == 1 || corner == 2) ? 1.0 : 0.0, cv = corner >= 2 ? 1.0 : 0.0;
          for (int n : {2, 5, 13, 20}) {  // 2^-13 ~ 1e-4, 2^-20 ~ 1e-6
            const double r = std::ldexp(1.0, -n);
            // Inside one ring's patch (1.3 r, 0.4 r from the corner) and steps that stay there.
            const double du0 = 1.3 * r, dv0 = 0.4 * r, h = 0.02 * r;
            auto at = [&](double a, double b) {
              return SurfacePoint{f, s, cu == 0.0 ? a : 1.0 - a, cv == 0.0 ? b : 1.0 - b};
            };
            const double su = cu == 0.0 ? 1.0 : -1.0, sv = cv == 0.0 ? 1.0 : -1.0;
            for (int dir = 0; dir < 2; ++dir) {
              auto shifted = [&](double k) { return dir == 0 ? at(du0 + k * h, dv0) : at(du0, dv0 + k * h); };
              const double sign = dir == 0 ? su : sv;
              for (int order = 0; order < 2; ++order) {  // first derivatives of N, then of N_u / N_v
                const int value = order == 0 ? 0 : 1 + dir, derivative = order == 0 ? 1 + dir : (dir == 0 ? 3 : 5);
                const Eigen::VectorXd fd = sign *
                                           (weights_at(ev, shifted(-2), value) - 8.0 * weights_at(ev, shifted(-1), value) +
                                            8.0 * weights_at(ev, shifted(1), value) - weights_at(ev, shifted(2), value)) /
                                           (12.0 * h);
                const Eigen::VectorXd exact = weights_at(ev, at(du0, dv0), derivative);
                const double magnitude = weights_at(ev, at(du0, dv0), value).cwiseAbs().maxCoeff();
                // 1e-8 of the derivative, or what the differences' own rounding allows.
                const double tolerance = 1e-8 * exact.cwiseAbs().maxCoeff() + 1e-14 * magnitude / h;
                EXPECT_LT((fd - exact).cwiseAbs().maxCoeff(), tolerance)
                    << name << " face " << f << "/" << s << " corner " << corner << " at 2^-" << n << " order " << order;
                ++checked;
              }
            }
          }
        }
      }
    }
  }
  EXPECT_GT(checked, 1000);
}

// At the extraordinary vertex itself: du and dv span the tangent plane (their normal is the
// limit of the normals around), the second derivatives are zero, and the normal is oriented
// like the face's.
TEST(LimitEvaluator, TangentsAtExtraordinaryVerticesSpanTheTangentPlane) {
  for (const auto& [name, mesh] : ev_meshes()) {
    auto ev = LimitEvaluator::create(mesh).value();
    std::vector<double> factors;
    int checked = 0;
    for (int32_t f = 0; f < mesh.num_faces(); ++f) {
      for (int32_t s = 0; s < ev.num_subfaces(f); ++s) {
        for (int corner = 0; corner < 4; ++corner) {
          if (!ev.ev_corner_weights(f, s, corner, 0.25, 2, factors)) continue;
          const double cu = (corner == 1 || corner == 2) ? 1.0 : 0.0, cv = corner >= 2 ? 1.0 : 0.0;
          const LimitSample at = ev.evaluate({f, s, cu, cv});
          const double d = 1e-30;  // the normal converges slowly at boundary vertices of many faces
          const LimitSample near = ev.evaluate({f, s, cu == 0.0 ? d : 1.0 - d, cv == 0.0 ? d : 1.0 - d});
          EXPECT_GT(at.normal().dot(near.normal()), 1.0 - 1e-8) << name << " face " << f << "/" << s << " corner " << corner;
          EXPECT_EQ(at.duu.norm() + at.duv.norm() + at.dvv.norm(), 0.0);
          ++checked;
        }
      }
    }
    EXPECT_GT(checked, 0) << name;
  }
}

// The quadrature support at extraordinary corners: the exact pressure integral of a cell
// against the sum of its rings (each integrated exactly), and weight factors near 1.
TEST(LimitEvaluator, ExtraordinaryCornerIntegralsAreTheSumsOfTheirRings) {
  ControlMesh mesh = test::load_asset_mesh("spot_control_mesh.obj");
  auto ev = LimitEvaluator::create(mesh).value();
  const double gx[5] = {0.04691007703066800, 0.23076534494715845, 0.5, 0.76923465505284155, 0.95308992296933200};
  const double gw[5] = {0.11846344252809454, 0.23931433524968324, 0.28444444444444444, 0.23931433524968324,
                        0.11846344252809454};
  int checked = 0;
  for (int32_t f = 0; f < mesh.num_faces() && checked < 12; ++f) {
    for (int32_t s = 0; s < ev.num_subfaces(f); ++s) {
      for (int corner = 0; corner < 4; ++corner) {
        const double size = 0.125;
        std::vector<double> factors;
        Eigen::Matrix3Xd exact;
        if (!ev.ev_corner_weights(f, s, corner, size, 4, factors)) continue;
        for (double x : factors) EXPECT_NEAR(x, 1.0, 1e-2);
        ASSERT_TRUE(ev.ev_corner_normal_weights(f, s, corner, size, mesh.positions(), exact));
        const std::vector<int32_t> support = ev.support(f);
        // The cell's rings, 5 x 5 Gauss points on each of their squares (degree 8 is exact).
        const double cu = (corner == 1 || corner == 2) ? 1.0 : 0.0, cv = corner >= 2 ? 1.0 : 0.0;
        Eigen::Matrix3Xd rings = Eigen::Matrix3Xd::Zero(3, static_cast<Eigen::Index>(support.size()));
        for (double h = size; h > 1e-9 * size; h *= 0.5) {
          const double q = 0.5 * h;
          for (auto [a, b] : std::array<std::array<double, 2>, 3>{{{q, 0.0}, {q, q}, {0.0, q}}}) {
            for (int i = 0; i < 5; ++i) {
              for (int j = 0; j < 5; ++j) {
                const double du = a + q * gx[i], dv = b + q * gx[j];
                const SurfacePoint p{f, s, cu == 0.0 ? du : 1.0 - du, cv == 0.0 ? dv : 1.0 - dv};
                const LimitSample x = ev.evaluate(p);
                const LimitStencil st = ev.stencil(p);
                for (size_t k = 0; k < st.size(); ++k) {
                  const auto col = std::find(support.begin(), support.end(), st.indices[k]) - support.begin();
                  rings.col(col) += (q * q * gw[i] * gw[j] * st.position[k]) * x.du.cross(x.dv);
                }
              }
            }
          }
        }
        EXPECT_LT((exact - rings).cwiseAbs().maxCoeff(), 1e-11 * rings.cwiseAbs().maxCoeff()) << "face " << f;
        ++checked;
      }
    }
  }
  EXPECT_GT(checked, 0);
}

// Topology the exact evaluation does not cover (an inner vertex of two faces, a non-manifold
// vertex) is evaluated by OpenSubdiv Bfr instead of refused.
TEST(LimitEvaluator, DegenerateTopologyIsEvaluatedOrRefused) {
  const ControlMesh pillow({Vec3(0, 0, 0), Vec3(1, 0, 0), Vec3(1, 1, 0), Vec3(0, 1, 0)},
                           std::vector<std::vector<int32_t>>{{0, 1, 2, 3}, {3, 2, 1, 0}});
  std::vector<Vec3> points;
  std::vector<std::vector<int32_t>> faces;
  for (int j = 0; j < 3; ++j) {
    for (int i = 0; i < 3; ++i) points.emplace_back(i, j, 0.0);
  }
  for (int j = 0; j < 2; ++j) {
    for (int i = 0; i < 2; ++i) faces.push_back({j * 3 + i, j * 3 + i + 1, (j + 1) * 3 + i + 1, (j + 1) * 3 + i});
  }
  // A second 2 x 2 grid touching the first only at its corner point 8.
  const auto base = static_cast<int32_t>(points.size());
  for (int j = 0; j < 3; ++j) {
    for (int i = 0; i < 3; ++i) {
      if (i > 0 || j > 0) points.emplace_back(2 + i, 2 + j, 0.5);
    }
  }
  auto id = [&](int i, int j) { return (i == 0 && j == 0) ? 8 : base + j * 3 + i - 1; };
  for (int j = 0; j < 2; ++j) {
    for (int i = 0; i < 2; ++i) faces.push_back({id(i, j), id(i + 1, j), id(i + 1, j + 1), id(i, j + 1)});
  }
  const ControlMesh bowtie(points, faces);
  auto ev = LimitEvaluator::create(pillow);
  ASSERT_TRUE(ev.ok()) << ev.error().message;
  for (int32_t f = 0; f < pillow.num_faces(); ++f) {
    const LimitStencil st = ev->stencil({f, 0, 0.3, 0.6});
    EXPECT_NEAR(sum(st.position), 1.0, 1e-12);
  }
  // Two pieces touching at one control point: a non-manifold vertex (PROTOCOL.md: 422), refused
  // by the one mesh validator with a message that says where and what to do.
  auto pinched = LimitEvaluator::create(bowtie);
  ASSERT_FALSE(pinched.ok());
  EXPECT_EQ(pinched.error().code, ErrorCode::kUnprocessable);
  EXPECT_NE(pinched.error().message.find("control point 8"), std::string::npos) << pinched.error().message;
  EXPECT_NE(pinched.error().message.find("pinches"), std::string::npos) << pinched.error().message;
}

}  // namespace
}  // namespace softshell
