#include "softshell/engine/solver.h"

#include <random>
#include <thread>

#include <gtest/gtest.h>

#include "limit_displacement.h"
#include "shell_benchmarks.h"
#include "softshell/request_validation.h"
#include "test_meshes.h"

namespace softshell::engine {
namespace {

Material material() { return Material{2.0e9, 0.35, 0.002, 1000.0}; }

std::shared_ptr<const ShellModel> build(const ControlMesh& mesh) {
  auto model = ShellModel::build(mesh, material());
  EXPECT_TRUE(model.ok()) << model.error().message;
  return *model;
}

// Limit displacement at a point for a solution.
using test::limit_displacement;

double relative_difference(const Eigen::VectorXd& a, const Eigen::VectorXd& b) {
  return (a - b).norm() / std::max(a.norm(), 1e-300);
}

// A plate clamped along one edge (two rows of control points) with forces and a grab.
struct Cantilever {
  ControlMesh mesh = test::make_grid(8, 4, 0.4, 0.2);
  std::vector<VertexConstraint> clamp() const {
    std::vector<VertexConstraint> out;
    for (int j = 0; j <= 4; ++j) {
      for (int i = 0; i <= 1; ++i) out.push_back({test::grid_index(8, i, j), kAxisAll, Vec3::Zero()});
    }
    return out;
  }
};

TEST(Solver, LimitConstraintMovesTheLimitPointExactly) {
  for (const char* name : {"catmark_helmet.obj", "catmark_gregory_test5.obj", "spot_control_mesh.obj"}) {
    ControlMesh mesh = test::load_asset_mesh(name);
    auto model = build(mesh);
    Solver solver(model, std::make_shared<FactorCache>());
    const double size = mesh.bounding_diagonal();
    DeformationRequest request;
    // Hold three far-apart points, pull a fourth.
    const int32_t f = mesh.num_faces();
    request.limit_constraints.push_back({{0, 0, 0.5, 0.5}, Vec3::Zero(), {}, {}});
    request.limit_constraints.push_back({{f / 3, 0, 0.25, 0.75}, Vec3::Zero(), {}, {}});
    request.limit_constraints.push_back({{f / 2, 0, 0.5, 0.1}, Vec3::Zero(), {}, {}});
    const Vec3 target(0.01 * size, -0.02 * size, 0.015 * size);
    const SurfacePoint grab{f - 1, 0, 0.3, 0.6};
    request.limit_constraints.push_back({grab, target, Vec3(0.001, 0.0, 0.002), {}});
    auto solution = solver.solve(request);
    ASSERT_TRUE(solution.ok()) << name << ": " << solution.error().message;
    EXPECT_LT((limit_displacement(*model, solution->displacement, grab) - target).norm(), 1e-9 * target.norm()) << name;
    for (int i = 0; i < 3; ++i) {
      EXPECT_LT(limit_displacement(*model, solution->displacement, request.limit_constraints[static_cast<size_t>(i)].point).norm(),
                1e-9 * target.norm())
          << name;
    }
    // The tangent constraint too.
    LimitStencil st = model->evaluator().stencil(grab);
    Vec3 du = Vec3::Zero();
    for (size_t k = 0; k < st.size(); ++k) du += st.du[k] * solution->displacement.segment<3>(3 * st.indices[k]);
    EXPECT_LT((du - Vec3(0.001, 0.0, 0.002)).norm(), 1e-9 * 0.002) << name;
  }
}

TEST(Solver, EveryPathGivesTheSameAnswer) {
  Cantilever c;
  auto model = build(c.mesh);
  auto cache = std::make_shared<FactorCache>();
  Solver solver(model, cache);
  DeformationRequest request;
  request.vertex_constraints = c.clamp();
  request.forces.push_back({test::grid_index(8, 8, 2), Vec3(0.0, 0.0, -1.0)});
  request.surface_load = Vec3(0.0, 0.0, -5.0);
  request.lagrange_constraints.push_back(
      {{test::grid_index(8, 8, 0), test::grid_index(8, 8, 4)}, {Vec3(1, 1, 1), Vec3(-1, -1, -1)}, Vec3::Zero()});
  request.limit_constraints.push_back({{13, 0, 0.4, 0.7}, Vec3(0.0, 0.0, 0.003), {}, {}});

  auto miss = solver.solve(request);
  ASSERT_TRUE(miss.ok()) << miss.error().message;
  EXPECT_FALSE(miss->stats.factor_cache_hit);
  auto hit = solver.solve(request);
  ASSERT_TRUE(hit.ok());
  EXPECT_TRUE(hit->stats.factor_cache_hit);
  EXPECT_EQ(hit->stats.factor_ms, 0.0);
  auto fallback = solver.solve_with_fallback(request);
  ASSERT_TRUE(fallback.ok()) << fallback.error().message;
  EXPECT_EQ(fallback->stats.path, SolvePath::kFallback);
  EXPECT_LT(relative_difference(miss->displacement, hit->displacement), 1e-12);
  EXPECT_LT(relative_difference(miss->displacement, fallback->displacement), 1e-9);

  // More prescribed DOFs than the cached factor has: extra rows on the same factor.
  DeformationRequest more = request;
  more.vertex_constraints.push_back({test::grid_index(8, 5, 2), kAxisZ, Vec3(0.0, 0.0, 0.001)});
  const auto before = cache->stats();
  auto extra = solver.solve(more);
  ASSERT_TRUE(extra.ok()) << extra.error().message;
  EXPECT_TRUE(extra->stats.factor_cache_hit);
  EXPECT_EQ(cache->stats().entries, before.entries);  // no new factorization
  auto extra_fallback = solver.solve_with_fallback(more);
  ASSERT_TRUE(extra_fallback.ok());
  EXPECT_LT(relative_difference(extra->displacement, extra_fallback->displacement), 1e-9);
  EXPECT_NEAR(extra->displacement[3 * test::grid_index(8, 5, 2) + 2], 0.001, 1e-15);
}

// A grab on a larger plate makes the forward sweep local (only the elimination-tree paths from
// the grabbed DOFs); a pressure reaches every DOF and takes the full sweep. Both must agree with
// the robust path.
TEST(Solver, LocalRightHandSidesSweepPartOfTheFactorWithTheSameAnswer) {
  const int n = 30;
  ControlMesh mesh = test::make_grid(n, n, 1.0, 1.0, [](double x, double) { return 0.2 * std::sin(3.0 * x); });
  auto model = build(mesh);
  Solver solver(model, std::make_shared<FactorCache>());
  DeformationRequest grab;
  for (int j = 0; j <= n; ++j) {
    for (int i = 0; i <= 1; ++i) grab.vertex_constraints.push_back({test::grid_index(n, i, j), kAxisAll, Vec3::Zero()});
  }
  grab.limit_constraints.push_back({{n * n - 5, 0, 0.3, 0.8}, Vec3(0.0, 0.01, -0.02), Vec3(0.0, 0.0, 0.001), {}});
  grab.forces.push_back({test::grid_index(n, n, n / 2), Vec3(0.0, 0.0, -3.0)});
  DeformationRequest pressed = grab;
  pressed.pressure = 200.0;

  for (const DeformationRequest* request : {&grab, &pressed}) {
    auto fast = solver.solve(*request);
    ASSERT_TRUE(fast.ok()) << fast.error().message;
    auto robust = solver.solve_with_fallback(*request);
    ASSERT_TRUE(robust.ok()) << robust.error().message;
    EXPECT_LT(relative_difference(fast->displacement, robust->displacement), 1e-9);
    if (request == &grab) {
      EXPECT_LT(fast->stats.forward_fraction, 0.5);  // local: a fraction of the factor
      EXPECT_GT(fast->stats.forward_fraction, 0.0);
    } else {
      EXPECT_EQ(fast->stats.forward_fraction, 1.0);  // the pressure reaches every DOF
    }
  }
}

TEST(Solver, FreeBodyHeldOnlyByLimitConstraints) {
  // No vertex constraint at all: the factor pins the rigid modes, the limit constraints hold them.
  ControlMesh mesh = test::load_asset_mesh("catmark_torus.obj");
  auto model = build(mesh);
  Solver solver(model, std::make_shared<FactorCache>());
  DeformationRequest request;
  request.limit_constraints.push_back({{0, 0, 0.5, 0.5}, Vec3::Zero(), {}, {}});
  request.limit_constraints.push_back({{10, 0, 0.5, 0.5}, Vec3::Zero(), {}, {}});
  request.limit_constraints.push_back({{20, 0, 0.5, 0.5}, Vec3(0.0, 0.0, 0.05), {}, {}});
  auto fast = solver.solve(request);
  ASSERT_TRUE(fast.ok()) << fast.error().message;
  auto slow = solver.solve_with_fallback(request);
  ASSERT_TRUE(slow.ok()) << slow.error().message;
  EXPECT_LT(relative_difference(fast->displacement, slow->displacement), 1e-9);
  EXPECT_LT((limit_displacement(*model, fast->displacement, {20, 0, 0.5, 0.5}) - Vec3(0, 0, 0.05)).norm(), 1e-11);
}

// The cube's checkerboard modes do not move its limit surface: limit constraints cannot hold them,
// so the solver fixes their amplitude to zero; a force on a control point would act on them.
TEST(Solver, InvisibleControlMeshModesAreGaugedAway) {
  ControlMesh cube = test::load_asset_mesh("catmark_cube.obj");
  auto model = build(cube);
  ASSERT_EQ(model->invisible_modes().size(), 3u);
  for (bool invisible : model->invisible_modes()) EXPECT_TRUE(invisible);
  Solver solver(model, std::make_shared<FactorCache>());
  DeformationRequest request;
  request.limit_constraints.push_back({{0, 0, 0.5, 0.5}, Vec3::Zero(), {}, {}});
  request.limit_constraints.push_back({{1, 0, 0.5, 0.5}, Vec3::Zero(), {}, {}});
  request.limit_constraints.push_back({{2, 0, 0.5, 0.5}, Vec3::Zero(), {}, {}});
  request.limit_constraints.push_back({{4, 0, 0.3, 0.5}, Vec3(0.0, 0.05, 0.0), {}, {}});
  auto fast = solver.solve(request);
  ASSERT_TRUE(fast.ok()) << fast.error().message;
  auto slow = solver.solve_with_fallback(request);
  ASSERT_TRUE(slow.ok()) << slow.error().message;
  EXPECT_LT(relative_difference(fast->displacement, slow->displacement), 1e-9);
  EXPECT_LT((limit_displacement(*model, fast->displacement, {4, 0, 0.3, 0.5}) - Vec3(0.0, 0.05, 0.0)).norm(), 1e-12);
  const Eigen::MatrixXd& modes = model->zero_energy_modes();
  for (Eigen::Index k = model->num_rigid_modes(); k < modes.cols(); ++k) {
    EXPECT_LT(std::abs(modes.col(k).dot(fast->displacement)), 1e-12);
  }
  request.forces.push_back({3, Vec3(0.0, 0.0, 1.0)});
  auto pushed = solver.solve(request);
  ASSERT_FALSE(pushed.ok());
  EXPECT_NE(pushed.error().message.find("surface force"), std::string::npos) << pushed.error().message;
}

TEST(Solver, UndeterminedSystemsSayWhatIsFree) {
  Cantilever c;
  auto model = build(c.mesh);
  Solver solver(model, std::make_shared<FactorCache>());
  DeformationRequest nothing;
  nothing.forces.push_back({3, Vec3(0, 0, 1)});
  for (bool fallback : {false, true}) {
    auto result = fallback ? solver.solve_with_fallback(nothing) : solver.solve(nothing);
    ASSERT_FALSE(result.ok());
    EXPECT_EQ(result.error().code, ErrorCode::kUnprocessable);
    EXPECT_NE(result.error().message.find("rigid-body motion"), std::string::npos) << result.error().message;
  }
  // z held along one line and on a second point, y at two points: the plate can still slide in x.
  DeformationRequest slide;
  for (int j = 0; j <= 4; ++j) slide.vertex_constraints.push_back({test::grid_index(8, 0, j), kAxisZ, Vec3::Zero()});
  slide.vertex_constraints.push_back({test::grid_index(8, 1, 0), kAxisZ, Vec3::Zero()});
  slide.vertex_constraints.push_back({test::grid_index(8, 0, 0), kAxisY, Vec3::Zero()});
  slide.vertex_constraints.push_back({test::grid_index(8, 8, 0), kAxisY, Vec3::Zero()});
  auto result = solver.solve(slide);
  ASSERT_FALSE(result.ok());
  EXPECT_NE(result.error().message.find("translate along (1, 0, 0)"), std::string::npos) << result.error().message;
  // A rotation about the held line.
  DeformationRequest hinge;
  for (int j = 0; j <= 4; ++j) hinge.vertex_constraints.push_back({test::grid_index(8, 0, j), kAxisAll, Vec3::Zero()});
  result = solver.solve(hinge);
  ASSERT_FALSE(result.ok());
  EXPECT_NE(result.error().message.find("rotate about the axis along (0, 1, 0)"), std::string::npos)
      << result.error().message;
}

TEST(Solver, ContradictionsAreRejectedAndRepetitionsAccepted) {
  Cantilever c;
  auto model = build(c.mesh);
  Solver solver(model, std::make_shared<FactorCache>());
  DeformationRequest base;
  base.vertex_constraints = c.clamp();

  DeformationRequest twice = base;  // the same prescribed value twice is fine
  twice.vertex_constraints.push_back({test::grid_index(8, 8, 0), kAxisZ, Vec3(0, 0, 0.01)});
  twice.vertex_constraints.push_back({test::grid_index(8, 8, 0), kAxisAll, Vec3(0.0, 0.0, 0.01)});
  EXPECT_TRUE(solver.solve(twice).ok());
  DeformationRequest conflict = base;
  conflict.vertex_constraints.push_back({test::grid_index(8, 8, 0), kAxisZ, Vec3(0, 0, 0.01)});
  conflict.vertex_constraints.push_back({test::grid_index(8, 8, 0), kAxisZ, Vec3(0, 0, 0.02)});
  auto r = solver.solve(conflict);
  ASSERT_FALSE(r.ok());
  EXPECT_EQ(r.error().code, ErrorCode::kUnprocessable);
  EXPECT_NE(r.error().message.find("different displacements"), std::string::npos);

  // The same grab sent twice: dependent but consistent.
  DeformationRequest grab = base;
  const SurfacePoint p{30, 0, 0.3, 0.3};
  grab.limit_constraints.push_back({p, Vec3(0, 0, 0.01), {}, {}});
  grab.limit_constraints.push_back({p, Vec3(0, 0, 0.01), {}, {}});
  auto ok = solver.solve(grab);
  ASSERT_TRUE(ok.ok()) << ok.error().message;
  auto ok_fallback = solver.solve_with_fallback(grab);
  ASSERT_TRUE(ok_fallback.ok()) << ok_fallback.error().message;
  EXPECT_LT(relative_difference(ok->displacement, ok_fallback->displacement), 1e-9);

  // The same point pulled two ways.
  grab.limit_constraints.back().displacement = Vec3(0, 0, 0.02);
  for (bool fallback : {false, true}) {
    r = fallback ? solver.solve_with_fallback(grab) : solver.solve(grab);
    ASSERT_FALSE(r.ok());
    EXPECT_EQ(r.error().code, ErrorCode::kUnprocessable);
    EXPECT_NE(r.error().message.find("contradict"), std::string::npos) << r.error().message;
  }

  // A Lagrange equation with zero coefficients: dropped if its value is 0, an error otherwise.
  DeformationRequest zero = base;
  zero.lagrange_constraints.push_back({{5}, {Vec3(0, 0, 0)}, Vec3(0, 0, 0)});
  EXPECT_TRUE(solver.solve(zero).ok());
  zero.lagrange_constraints.back().values = Vec3(0, 1, 0);
  r = solver.solve(zero);
  ASSERT_FALSE(r.ok());
  EXPECT_EQ(r.error().code, ErrorCode::kUnprocessable);

  // A limit constraint on clamped control points that asks them to move.
  DeformationRequest stuck = base;
  stuck.limit_constraints.push_back({{0, 0, 0.0, 0.0}, Vec3(0, 0, 0.01), {}, {}});
  r = solver.solve(stuck);
  ASSERT_FALSE(r.ok());
  EXPECT_NE(r.error().message.find("contradicts the vertex constraints"), std::string::npos) << r.error().message;
}

// Requests are validated once at the boundary (validate_request); the engine asserts that
// precondition, so a malformed request that reaches it is refused as a bug of the caller, naming
// the bad element, and never solved.
TEST(Solver, MalformedRequestsBreakItsPreconditionAndAreRefused) {
  Cantilever c;
  auto model = build(c.mesh);
  Solver solver(model, std::make_shared<FactorCache>());
  auto expect_invalid = [&](DeformationRequest request, const char* what) {
    const Result<void> valid = validate_request(request, {model->num_control_points(), &model->evaluator()});
    ASSERT_FALSE(valid.ok()) << what;
    auto r = solver.solve(request);
    ASSERT_FALSE(r.ok()) << what;
    EXPECT_EQ(r.error().code, ErrorCode::kInternal) << what << ": " << r.error().message;
    EXPECT_NE(r.error().message.find(valid.error().message), std::string::npos) << what << ": " << r.error().message;
  };
  DeformationRequest base;
  base.vertex_constraints = c.clamp();
  DeformationRequest r = base;
  r.vertex_constraints.push_back({999, kAxisAll, Vec3::Zero()});
  expect_invalid(r, "index");
  r = base;
  r.vertex_constraints.push_back({3, 0, Vec3::Zero()});
  expect_invalid(r, "mask 0");
  r = base;
  r.vertex_constraints.push_back({3, 8, Vec3::Zero()});
  expect_invalid(r, "mask 8");
  r = base;
  r.forces.push_back({3, Vec3(std::nan(""), 0, 0)});
  expect_invalid(r, "NaN force");
  r = base;
  r.limit_constraints.push_back({{0, 0, 1.5, 0.0}, Vec3::Zero(), {}, {}});
  expect_invalid(r, "u out of range");
  r = base;
  r.lagrange_constraints.push_back({{1, 2}, {Vec3(1, 1, 1)}, Vec3::Zero()});
  expect_invalid(r, "coefficient count");
  r = base;
  r.pressure = std::numeric_limits<double>::infinity();
  expect_invalid(r, "pressure");
}

TEST(Solver, ConcurrentSolvesShareOneFactor) {
  Cantilever c;
  auto model = build(c.mesh);
  auto cache = std::make_shared<FactorCache>();
  Solver solver(model, cache);
  std::vector<Eigen::VectorXd> answers(8);
  std::vector<std::thread> threads;
  for (int t = 0; t < 8; ++t) {
    threads.emplace_back([&, t] {
      DeformationRequest request;
      request.vertex_constraints = c.clamp();
      request.forces.push_back({test::grid_index(8, 8, t % 5), Vec3(0.0, 0.0, -1.0 - t)});
      auto r = solver.solve(request);
      if (r.ok()) answers[static_cast<size_t>(t)] = r->displacement;
    });
  }
  for (auto& t : threads) t.join();
  EXPECT_EQ(cache->stats().entries, 1u);
  EXPECT_EQ(cache->stats().misses, 1u);
  for (int t = 0; t < 8; ++t) {
    DeformationRequest request;
    request.vertex_constraints = c.clamp();
    request.forces.push_back({test::grid_index(8, 8, t % 5), Vec3(0.0, 0.0, -1.0 - t)});
    auto serial = solver.solve_with_fallback(request);
    ASSERT_TRUE(serial.ok());
    ASSERT_EQ(answers[static_cast<size_t>(t)].size(), serial->displacement.size());
    EXPECT_LT(relative_difference(answers[static_cast<size_t>(t)], serial->displacement), 1e-9);
  }
}

TEST(Solver, CacheStaysWithinItsBudget) {
  Cantilever c;
  auto model = build(c.mesh);
  auto cache = std::make_shared<FactorCache>(1);  // 1 byte: nothing can stay
  Solver solver(model, cache);
  DeformationRequest request;
  request.vertex_constraints = c.clamp();
  request.forces.push_back({40, Vec3(0, 0, -1)});
  ASSERT_TRUE(solver.solve(request).ok());
  EXPECT_EQ(cache->stats().entries, 0u);
  EXPECT_EQ(cache->stats().bytes, 0u);
  EXPECT_GE(cache->stats().evictions, 1u);

  // Room for one factor: the least recently used one goes.
  auto one = std::make_shared<FactorCache>(size_t{1} << 30);
  Solver s2(model, one);
  ASSERT_TRUE(s2.solve(request).ok());
  const size_t bytes = one->stats().bytes;
  ASSERT_GT(bytes, 0u);
  auto tight = std::make_shared<FactorCache>(bytes + bytes / 2);
  Solver s3(model, tight);
  ASSERT_TRUE(s3.solve(request).ok());
  // The other end clamped: not a superset of the cached set, so a second factor is needed.
  DeformationRequest other;
  for (int j = 0; j <= 4; ++j) {
    for (int i = 7; i <= 8; ++i) other.vertex_constraints.push_back({test::grid_index(8, i, j), kAxisAll, Vec3::Zero()});
  }
  other.forces.push_back({3, Vec3(0, 0, -1)});
  ASSERT_TRUE(s3.solve(other).ok());
  EXPECT_LE(tight->stats().bytes, tight->stats().budget);
  EXPECT_EQ(tight->stats().entries, 1u);
  EXPECT_EQ(tight->stats().evictions, 1u);
}

}  // namespace
}  // namespace softshell::engine
