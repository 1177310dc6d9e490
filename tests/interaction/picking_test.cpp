#include "softshell/picking.h"

#include <cmath>
#include <random>

#include <gtest/gtest.h>

#include "test_meshes.h"

namespace softshell {
namespace {

// Reference: Moller-Trumbore against every triangle (nearest hit, both sides).
std::optional<std::pair<int32_t, double>> brute_force(const Tessellation& t, const Ray& ray) {
  std::optional<std::pair<int32_t, double>> best;
  for (size_t i = 0; i < t.triangles().size(); ++i) {
    const auto& tri = t.triangles()[i];
    const Vec3& a = t.vertices()[static_cast<size_t>(tri[0])];
    const Vec3 e1 = t.vertices()[static_cast<size_t>(tri[1])] - a, e2 = t.vertices()[static_cast<size_t>(tri[2])] - a;
    const Vec3 p = ray.direction.cross(e2);
    const double det = e1.dot(p);
    if (std::abs(det) < 1e-300) continue;
    const Vec3 s = ray.origin - a;
    const double u = s.dot(p) / det;
    const Vec3 q = s.cross(e1);
    const double v = ray.direction.dot(q) / det;
    const double tt = e2.dot(q) / det;
    if (u < 0 || v < 0 || u + v > 1 || tt < ray.t_min || tt > ray.t_max) continue;
    if (!best || tt < best->second) best = std::make_pair(static_cast<int32_t>(i), tt);
  }
  return best;
}

// Rays from a sphere around the object aimed at random points of random triangles.
std::vector<Ray> aimed_rays(const Tessellation& t, int count, uint32_t seed) {
  std::mt19937 rng(seed);
  std::uniform_real_distribution<double> uni(0.0, 1.0);
  std::normal_distribution<double> normal;
  Vec3 lo = t.vertices()[0], hi = lo;
  for (const Vec3& v : t.vertices()) {
    lo = lo.cwiseMin(v);
    hi = hi.cwiseMax(v);
  }
  const Vec3 centre = 0.5 * (lo + hi);
  const double size = (hi - lo).norm();
  std::vector<Ray> rays;
  for (int i = 0; i < count; ++i) {
    const auto& tri = t.triangles()[rng() % t.triangles().size()];
    double a = uni(rng), b = uni(rng);
    if (a + b > 1.0) { a = 1.0 - a; b = 1.0 - b; }
    const Vec3 target = (1 - a - b) * t.vertices()[static_cast<size_t>(tri[0])] + a * t.vertices()[static_cast<size_t>(tri[1])] +
                        b * t.vertices()[static_cast<size_t>(tri[2])];
    Vec3 dir(normal(rng), normal(rng), normal(rng));
    Ray ray;
    ray.origin = centre + 1.5 * size * dir.normalized();
    ray.direction = (target - ray.origin) * (0.5 + uni(rng));  // lengths other than 1 on purpose
    rays.push_back(ray);
  }
  return rays;
}

double ray_distance(const Ray& ray, const Vec3& x) {
  const Vec3 d = ray.direction.normalized();
  const Vec3 r = x - ray.origin;
  return (r - r.dot(d) * d).norm();
}

TEST(Picking, BvhAgreesWithBruteForce) {
  ControlMesh mesh = test::load_asset_mesh("catmark_torus.obj");
  auto ev = LimitEvaluator::create(mesh).value();
  auto t = Tessellation::create(ev, 3).value();
  auto bvh = TriangleBvh::build(t.vertices(), t.triangles()).value();
  EXPECT_EQ(bvh.num_triangles(), static_cast<int32_t>(t.triangles().size()));
  EXPECT_GT(bvh.stats().leaves, 1);
  std::mt19937 rng(3);
  std::normal_distribution<double> normal;
  int hits = 0;
  for (int i = 0; i < 400; ++i) {
    Ray ray;
    // Towards a point near the surface (hits and misses, inside and outside the torus).
    const Vec3 target = t.vertices()[rng() % t.vertices().size()] + 0.3 * Vec3(normal(rng), normal(rng), normal(rng));
    ray.origin = Vec3(normal(rng), normal(rng), normal(rng)) * 3.0;
    ray.direction = target - ray.origin;
    const auto expected = brute_force(t, ray);
    const auto got = bvh.intersect(ray);
    ASSERT_EQ(expected.has_value(), got.has_value()) << "ray " << i;
    if (!got) continue;
    ++hits;
    EXPECT_NEAR(got->t, expected->second, 1e-12 * (1.0 + expected->second)) << "ray " << i;
    const auto& tri = t.triangles()[static_cast<size_t>(got->triangle)];
    Vec3 p = Vec3::Zero();
    double sum = 0.0;
    for (size_t c = 0; c < 3; ++c) {
      EXPECT_GE(got->barycentric[c], 0.0);
      sum += got->barycentric[c];
      p += got->barycentric[c] * t.vertices()[static_cast<size_t>(tri[c])];
    }
    EXPECT_NEAR(sum, 1.0, 1e-12);
    EXPECT_LT((p - (ray.origin + got->t * ray.direction)).norm(), 1e-10);
    EXPECT_LT((p - got->position).norm(), 1e-12);
  }
  EXPECT_GT(hits, 50);
  EXPECT_LT(hits, 390);
}

TEST(Picking, RaysThroughSharedEdgesAndVerticesNeverSlipThrough) {
  // Watertightness: aim exactly at tessellation vertices and edge midpoints of a curved grid.
  ControlMesh mesh = test::make_grid(4, 4, 1.0, 1.0, [](double x, double y) { return 0.1 * std::sin(3 * x) * y; });
  auto ev = LimitEvaluator::create(mesh).value();
  auto t = Tessellation::create(ev, 2).value();
  auto picker = Picker::create(t).value();
  int tested = 0;
  for (const auto& tri : t.triangles()) {
    for (size_t c = 0; c < 3; ++c) {
      const Vec3 a = t.vertices()[static_cast<size_t>(tri[c])];
      const Vec3 b = t.vertices()[static_cast<size_t>(tri[(c + 1) % 3])];
      for (const Vec3& target : {a, Vec3(0.5 * (a + b))}) {
        // Shared edges and vertices only: at the open boundary a ray may pass outside.
        if (target.x() < 1e-9 || target.x() > 1 - 1e-9 || target.y() < 1e-9 || target.y() > 1 - 1e-9) continue;
        Ray ray{target + Vec3(0.01, -0.02, 1.0), Vec3(-0.01, 0.02, -1.0)};
        auto hit = picker.intersect(ray).value();
        ASSERT_TRUE(hit.has_value()) << "slipped through at " << target.transpose();
        EXPECT_NEAR(hit->t, 1.0, 1e-9);
        ++tested;
      }
    }
  }
  EXPECT_GT(tested, 500);
}

TEST(Picking, BadRaysAreErrorsNotCrashes) {
  auto ev = LimitEvaluator::create(test::load_asset_mesh("catmark_cube.obj")).value();
  auto t = Tessellation::create(ev, 2).value();
  auto picker = Picker::create(t).value();
  const double nan = std::numeric_limits<double>::quiet_NaN();
  const double inf = std::numeric_limits<double>::infinity();
  const std::vector<Ray> bad = {
      {Vec3(nan, 0, 0), Vec3(0, 0, 1)},     {Vec3(0, 0, 5), Vec3(0, nan, -1)}, {Vec3(0, 0, 5), Vec3::Zero()},
      {Vec3(inf, 0, 0), Vec3(0, 0, 1)},     {Vec3(0, 0, 5), Vec3(0, 0, -inf)},
      {Vec3(0, 0, 5), Vec3(0, 0, -1), 2.0, 1.0}, {Vec3(0, 0, 5), Vec3(0, 0, -1), nan, 1.0},
      {Vec3(0, 0, 5), Vec3(0, 0, -1), 0.0, nan},
  };
  for (const Ray& ray : bad) {
    auto r = picker.pick(ray);
    ASSERT_FALSE(r.ok());
    EXPECT_EQ(r.error().code, ErrorCode::kInvalidArgument);
    EXPECT_FALSE(r.error().message.empty());
    EXPECT_FALSE(picker.intersect(ray).ok());
  }
  // Bad refinement options and start points.
  PickOptions options;
  options.refinement.max_iterations = -1;
  EXPECT_EQ(picker.pick({Vec3(0, 0, 5), Vec3(0, 0, -1)}, options).error().code, ErrorCode::kInvalidArgument);
  EXPECT_FALSE(picker.refiner().refine({Vec3(0, 0, 5), Vec3(0, 0, -1)}, {99, 0, 0.5, 0.5}, t.control_positions()).ok());
  EXPECT_FALSE(picker.refiner().refine({Vec3(0, 0, 5), Vec3(0, 0, -1)}, {0, 0, 1.5, 0.5}, t.control_positions()).ok());
  EXPECT_FALSE(picker.refiner().refine({Vec3(0, 0, 5), Vec3(0, 0, -1)}, {0, 0, 0.5, 0.5}, {Vec3::Zero()}).ok());
  // Bad BVH input.
  EXPECT_EQ(TriangleBvh::build(t.vertices(), std::vector<std::array<int32_t, 3>>{{0, 1, 99999}}).error().code,
            ErrorCode::kInvalidArgument);
  std::vector<Vec3> nan_vertices = t.vertices();
  nan_vertices[3].x() = nan;
  EXPECT_EQ(TriangleBvh::build(nan_vertices, t.triangles()).error().code, ErrorCode::kInvalidArgument);
  auto bvh = TriangleBvh::build(t.vertices(), t.triangles()).value();
  EXPECT_FALSE(bvh.refit(nan_vertices).ok());
  EXPECT_FALSE(bvh.refit(std::vector<Vec3>(3, Vec3::Zero())).ok());
}

TEST(Picking, MissesReturnNoHit) {
  auto ev = LimitEvaluator::create(test::load_asset_mesh("catmark_cube.obj")).value();
  auto t = Tessellation::create(ev, 3).value();
  auto picker = Picker::create(t).value();
  // Pointing away, passing beside, and stopping short (t_max) of the surface.
  EXPECT_FALSE(picker.pick({Vec3(0, 0, 5), Vec3(0, 0, 1)}).value().has_value());
  EXPECT_FALSE(picker.pick({Vec3(5, 0, 5), Vec3(0, 0, -1)}).value().has_value());
  EXPECT_FALSE(picker.pick({Vec3(0, 0, 5), Vec3(0, 0, -1), 0.0, 3.0}).value().has_value());
  EXPECT_TRUE(picker.pick({Vec3(0, 0, 5), Vec3(0, 0, -1), 0.0, 6.0}).value().has_value());
  // An empty BVH never hits.
  auto empty = TriangleBvh::build({}, {}).value();
  EXPECT_FALSE(empty.intersect({Vec3(0, 0, 5), Vec3(0, 0, -1)}).has_value());
}

TEST(Picking, BackFacesCanBeCulled) {
  ControlMesh mesh = test::make_grid(3, 3);
  auto ev = LimitEvaluator::create(mesh).value();
  auto t = Tessellation::create(ev, 2).value();
  auto picker = Picker::create(t).value();
  PickOptions cull;
  cull.cull_back_faces = true;
  const Ray from_above{Vec3(0.4, 0.6, 1.0), Vec3(0, 0, -1)}, from_below{Vec3(0.4, 0.6, -1.0), Vec3(0, 0, 1)};
  EXPECT_TRUE(picker.pick(from_above, cull).value().has_value());
  EXPECT_FALSE(picker.pick(from_below, cull).value().has_value());
  EXPECT_TRUE(picker.pick(from_below).value().has_value());
}

// The refined point lies on the ray (to 1e-9 of the object's size) and on the limit surface, for
// meshes with n-gons, extraordinary vertices, creases and boundaries.
TEST(Picking, RefinedPointLiesOnRayAndLimitSurface) {
  for (const char* name : {"catmark_torus.obj", "catmark_nonquads.obj", "catmark_helmet.obj", "blub_control_mesh.obj",
                           "catmark_cube.obj", "catmark_gregory_test5.obj", "catmark_tent.obj"}) {
    ControlMesh mesh = test::load_asset_mesh(name);
    auto ev = LimitEvaluator::create(mesh).value();
    auto t = Tessellation::create(ev, 2).value();
    auto picker = Picker::create(t).value();
    const double size = mesh.bounding_diagonal();
    int hits = 0, converged = 0, ngon_hits = 0, crossings = 0;
    for (const Ray& ray : aimed_rays(t, 300, 11)) {
      auto pick = picker.pick(ray).value();
      ASSERT_TRUE(pick.has_value()) << name;  // aimed rays always hit something
      ++hits;
      ASSERT_TRUE(ev.check(pick->point).ok());
      const LimitSample s = ev.evaluate(pick->point);
      EXPECT_LT((s.position - pick->position).norm(), 1e-12 * size);
      const Vec3 n = s.normal();
      crossings += pick->face_crossings > 0 ? 1 : 0;
      ngon_hits += mesh.face_size(pick->point.face) != 4 ? 1 : 0;
      if (pick->status == RefineStatus::kConverged) {
        ++converged;
        EXPECT_LE(ray_distance(ray, s.position), 1e-9 * size) << name;
        EXPECT_LE(pick->distance_to_ray, 1e-9 * size);
        EXPECT_NEAR((ray.origin + pick->t * ray.direction - s.position).norm(), 0.0, 1e-9 * size);
        // The refined point is close to the estimate (the estimate is within the chordal error).
        EXPECT_LT((ev.evaluate(pick->estimate).position - s.position).norm(), 50 * t.chordal_error() + 1e-12);
      } else {
        // Only grazing rays, rays past an open boundary, or rays that hit the triangles where
        // they stick out of the limit surface (near a silhouette, within the chordal error: the
        // ray then passes the exact surface) may fail to converge.
        const double cosine = std::abs(n.dot(ray.direction.normalized()));
        EXPECT_TRUE(cosine < 0.2 || pick->status == RefineStatus::kAtBoundary ||
                    pick->distance_to_ray <= t.chordal_error())
            << name << ": not converged at cos " << cosine << ", distance " << pick->distance_to_ray / size;
      }
    }
    EXPECT_GE(converged, hits * 97 / 100) << name;
    if (std::string(name) == "catmark_nonquads.obj") {
      EXPECT_GT(ngon_hits, 10);
    }
    RecordProperty(std::string(name) + "_crossings", crossings);
  }
}

// The unrefined estimate (paper Section 5.1) approaches the refined point as the level grows.
TEST(Picking, EstimateErrorShrinksWithTheLevel) {
  for (const char* name : {"catmark_torus.obj", "catmark_nonquads.obj", "spot_control_mesh.obj"}) {
    ControlMesh mesh = test::load_asset_mesh(name);
    auto ev = LimitEvaluator::create(mesh).value();
    const double size = mesh.bounding_diagonal();
    auto t1 = Tessellation::create(ev, 1).value();
    const std::vector<Ray> rays = aimed_rays(t1, 200, 7);
    double previous = std::numeric_limits<double>::infinity();
    for (int level = 1; level <= 5; ++level) {
      auto t = Tessellation::create(ev, level).value();
      auto picker = Picker::create(t).value();
      double sum = 0.0;
      int n = 0;
      for (const Ray& ray : rays) {
        auto pick = picker.pick(ray).value();
        if (!pick || pick->status != RefineStatus::kConverged) continue;
        sum += (ev.evaluate(pick->estimate).position - pick->position).norm();
        ++n;
      }
      ASSERT_GT(n, 150) << name << " level " << level;
      const double mean = sum / n / size;
      // Second order on smooth parts: about 4x a level; require 2x.
      EXPECT_LT(mean, 0.5 * previous) << name << " level " << level;
      previous = mean;
    }
    EXPECT_LT(previous, 1e-3) << name;
  }
}

// Newton started on the wrong face walks across seams (quad-quad, quad-n-gon, sub-face to
// sub-face) to the intersection.
TEST(Picking, RefinementCrossesSeamsAndSubfaces) {
  ControlMesh mesh = test::load_asset_mesh("catmark_nonquads.obj");
  auto ev = LimitEvaluator::create(mesh).value();
  const RayRefiner refiner(ev);
  const double size = mesh.bounding_diagonal();
  std::mt19937 rng(2);
  std::uniform_real_distribution<double> uni(0.05, 0.95);
  int crossed = 0, tried = 0;
  for (int32_t f = 0; f < mesh.num_faces(); ++f) {
    for (int32_t k = 0; k < ev.num_subfaces(f); ++k) {
      // Target: a point of (f, k); the ray comes in along its normal.
      const SurfacePoint target{f, k, uni(rng), uni(rng)};
      const LimitSample s = ev.evaluate(target);
      const Ray ray{s.position + 0.3 * size * s.normal(), -s.normal()};
      // Start on each neighbour across the four sides, as far from the seam as the neighbour allows.
      for (int side = 0; side < 4; ++side) {
        SurfacePoint on_edge = target;
        if (side == 0) on_edge.v = 0.0;
        if (side == 1) on_edge.u = 1.0;
        if (side == 2) on_edge.v = 1.0;
        if (side == 3) on_edge.u = 0.0;
        auto start = refiner.across(on_edge, side);
        if (!start) continue;
        // Same limit point on both sides of the seam.
        EXPECT_LT((ev.evaluate(*start).position - ev.evaluate(on_edge).position).norm(), 1e-12 * size);
        // Move the start into the neighbour's interior.
        start->u = std::clamp(start->u, 0.3, 0.7);
        start->v = std::clamp(start->v, 0.3, 0.7);
        auto r = refiner.refine(ray, *start, mesh.positions()).value();
        ++tried;
        ASSERT_EQ(r.status, RefineStatus::kConverged) << "face " << f << " sub " << k << " side " << side;
        EXPECT_LT((r.position - s.position).norm(), 1e-8 * size);
        crossed += r.face_crossings > 0 ? 1 : 0;
      }
    }
  }
  EXPECT_GT(tried, 40);
  EXPECT_EQ(crossed, tried);
}

TEST(Picking, AcrossIsAnInvolution) {
  for (const char* name : {"catmark_nonquads.obj", "catmark_torus.obj", "catmark_tent.obj"}) {
    ControlMesh mesh = test::load_asset_mesh(name);
    auto ev = LimitEvaluator::create(mesh).value();
    const RayRefiner refiner(ev);
    for (int32_t f = 0; f < mesh.num_faces(); ++f) {
      for (int32_t k = 0; k < ev.num_subfaces(f); ++k) {
        for (int side = 0; side < 4; ++side) {
          SurfacePoint p{f, k, 0.3, 0.3};
          if (side == 0) p.v = 0.0;
          if (side == 1) p.u = 1.0;
          if (side == 2) p.v = 1.0;
          if (side == 3) p.u = 0.0;
          auto q = refiner.across(p, side);
          if (!q) continue;
          // Which side of q's domain it lies on, then back across.
          const int back = q->v == 0.0 ? 0 : q->u == 1.0 ? 1 : q->v == 1.0 ? 2 : 3;
          auto r = refiner.across(*q, back);
          ASSERT_TRUE(r.has_value());
          EXPECT_EQ(r->face, p.face);
          EXPECT_EQ(r->subface, p.subface);
          EXPECT_NEAR(r->u, p.u, 1e-15);
          EXPECT_NEAR(r->v, p.v, 1e-15);
        }
      }
    }
  }
  // An open boundary has nothing across.
  ControlMesh grid = test::make_grid(2, 2);
  const RayRefiner refiner(LimitEvaluator::create(grid).value());
  EXPECT_FALSE(refiner.across({0, 0, 0.5, 0.0}, 0).has_value());
  EXPECT_TRUE(refiner.across({0, 0, 1.0, 0.5}, 1).has_value());
  EXPECT_THROW((void)refiner.across({0, 0, 0.5, 0.0}, 4), Exception);
}

TEST(Picking, RayPastAnOpenBoundaryStopsOnTheBoundary) {
  ControlMesh grid = test::make_grid(3, 3, 1.0, 1.0, [](double x, double y) { return 0.2 * x * y; });
  auto ev = LimitEvaluator::create(grid).value();
  const RayRefiner refiner(ev);
  // Vertical ray just outside the edge y = 0 (the limit boundary is the B-spline of the boundary
  // control points: the line y = 0 here).
  const Ray ray{Vec3(0.5, -0.01, 1.0), Vec3(0, 0, -1)};
  auto r = refiner.refine(ray, {1, 0, 0.5, 0.2}, grid.positions()).value();
  EXPECT_EQ(r.status, RefineStatus::kAtBoundary);
  EXPECT_EQ(r.point.v, 0.0);
  EXPECT_NEAR(r.position.y(), 0.0, 1e-12);
  EXPECT_NEAR(r.position.x(), 0.5, 1e-6);
  EXPECT_NEAR(r.distance_to_ray, 0.01, 1e-6);
}

TEST(Picking, GhostFacesAreNeverPicked) {
  ControlMesh grid = test::make_grid(5, 5);
  grid.set_boundary(BoundaryMode::kNone);
  auto ev = LimitEvaluator::create(grid).value();
  auto t = Tessellation::create(ev, 2).value();
  auto picker = Picker::create(t).value();
  for (const Ray& ray : aimed_rays(t, 100, 5)) {
    auto pick = picker.pick(ray).value();
    ASSERT_TRUE(pick.has_value());
    EXPECT_TRUE(ev.has_limit_surface(pick->point.face));
  }
  // A ray over the ghost ring misses the limit surface.
  EXPECT_FALSE(picker.pick({Vec3(0.1, 0.1, 1.0), Vec3(0, 0, -1)}).value().has_value());
}

// After a deformation, Tessellation::update + Picker::refit picks the deformed limit surface,
// exactly as a picker built from scratch on the deformed mesh.
TEST(Picking, RefitFollowsTheDeformedSurface) {
  ControlMesh mesh = test::load_asset_mesh("catmark_nonquads.obj");
  auto ev = LimitEvaluator::create(mesh).value();
  auto t = Tessellation::create(ev, 3).value();
  auto picker = Picker::create(t).value();
  const double size = mesh.bounding_diagonal();
  std::vector<Vec3> deformed = mesh.positions();
  for (Vec3& p : deformed) p += Vec3(0.1 * std::sin(3 * p.y()), 0.05 * p.x() * p.x(), 0.1 * std::cos(2 * p.x())) * size;
  t.update(deformed);
  ASSERT_TRUE(picker.refit().ok());

  ControlMesh moved = mesh;
  moved.positions() = deformed;
  auto ev2 = LimitEvaluator::create(moved).value();
  auto t2 = Tessellation::create(ev2, 3).value();
  auto fresh = Picker::create(t2).value();
  int hits = 0;
  for (const Ray& ray : aimed_rays(t2, 200, 9)) {
    auto a = picker.pick(ray).value();
    auto b = fresh.pick(ray).value();
    ASSERT_EQ(a.has_value(), b.has_value());
    if (!a) continue;
    ++hits;
    EXPECT_EQ(a->hit.triangle, b->hit.triangle);
    EXPECT_NEAR(a->hit.t, b->hit.t, 1e-10);
    if (a->status == RefineStatus::kConverged) {
      EXPECT_LE(ray_distance(ray, ev.evaluate(a->point, deformed).position), 1e-9 * size);
      EXPECT_LT((a->position - b->position).norm(), 1e-9 * size);
    }
  }
  EXPECT_GT(hits, 150);
  EXPECT_GE(picker.bvh().stats().refit_ms, 0.0);

  // A rebuilt tree answers the same.
  auto rebuilt = Picker::create(t).value();
  ASSERT_TRUE(rebuilt.rebuild().ok());
  for (const Ray& ray : aimed_rays(t2, 50, 10)) {
    auto a = picker.pick(ray).value();
    auto b = rebuilt.pick(ray).value();
    ASSERT_EQ(a.has_value(), b.has_value());
    if (a) {
      EXPECT_EQ(a->hit.triangle, b->hit.triangle);
    }
  }
}

TEST(Picking, UnrefinedPickReportsTheEstimate) {
  auto ev = LimitEvaluator::create(test::load_asset_mesh("catmark_torus.obj")).value();
  auto t = Tessellation::create(ev, 2).value();
  auto picker = Picker::create(t).value();
  PickOptions options;
  options.refine = false;
  const Ray ray = aimed_rays(t, 1, 4)[0];
  auto pick = picker.pick(ray, options).value();
  ASSERT_TRUE(pick.has_value());
  EXPECT_EQ(pick->point, pick->estimate);
  EXPECT_EQ(pick->iterations, 0);
  EXPECT_GT(pick->distance_to_ray, 0.0);
  auto refined = picker.pick(ray).value();
  EXPECT_LT(refined->distance_to_ray, pick->distance_to_ray);
  EXPECT_EQ(refined->estimate, pick->estimate);
}

}  // namespace
}  // namespace softshell
