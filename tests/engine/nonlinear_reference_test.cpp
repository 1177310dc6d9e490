// The nonlinear model against published large-deflection solutions (not against itself). Each
// test prints its convergence table.
#include <cmath>
#include <cstdio>

#include <gtest/gtest.h>

#include "softshell/engine/nonlinear_solver.h"
#include "softshell/level_of_detail.h"
#include "test_meshes.h"

namespace softshell::engine {
namespace {

// A strip [0, L] x [0, b] in z = 0 with nx x ny faces and one ring of ghost faces around it
// (boundary mode "none"): the physical faces are a full B-spline space up to their edges, so a
// clamp is exact (limit constraints on position and tangents) and the other edges are free.
struct Strip {
  ControlMesh mesh;
  int nx = 0, ny = 0;
  double length = 1.0, width = 0.1;
  // The face and (u, v) of strip parameter (s, t) in [0, 1]^2.
  SurfacePoint at(double s, double t) const {
    const int fi = std::min(static_cast<int>(s * nx), nx - 1), fj = std::min(static_cast<int>(t * ny), ny - 1);
    return SurfacePoint{(fj + 1) * (nx + 2) + fi + 1, 0, s * nx - fi, t * ny - fj};
  }
};

Strip make_strip(int nx, int ny, double length, double width) {
  Strip s;
  s.nx = nx;
  s.ny = ny;
  s.length = length;
  s.width = width;
  const double hx = length / nx, hy = width / ny;
  std::vector<Vec3> positions;
  for (int j = 0; j <= ny + 2; ++j) {
    for (int i = 0; i <= nx + 2; ++i) positions.emplace_back((i - 1) * hx, (j - 1) * hy, 0.0);
  }
  std::vector<std::vector<int32_t>> quads;
  const int row = nx + 3;
  for (int j = 0; j < ny + 2; ++j) {
    for (int i = 0; i < nx + 2; ++i) quads.push_back({j * row + i, j * row + i + 1, (j + 1) * row + i + 1, (j + 1) * row + i});
  }
  s.mesh = ControlMesh(std::move(positions), quads);
  s.mesh.set_boundary(BoundaryMode::kNone);
  return s;
}

Vec3 limit_displacement(const ShellModel& model, const Eigen::VectorXd& u, const SurfacePoint& p) {
  LimitStencil st = model.evaluator().stencil(p);
  Vec3 d = Vec3::Zero();
  for (size_t k = 0; k < st.size(); ++k) d += st.position[k] * u.segment<3>(3 * st.indices[k]);
  return d;
}

// Cantilever strip (nu = 0, so it bends as a beam), clamped at x = 0, a dead vertical load P at
// the free end spread evenly along it. Mattiasson (1981), elliptic-integral solution of the
// elastica: tip deflection / L, vertical and horizontal, for P L^2 / EI = 1, 2, 5, 10.
TEST(NonlinearReference, LargeDeflectionCantileverFollowsTheElastica) {
  constexpr double kLength = 1.0, kWidth = 0.1, kThickness = 0.01, kYoung = 1.0e7;
  const double ei = kYoung * kWidth * kThickness * kThickness * kThickness / 12.0;
  const double loads[] = {1.0, 2.0, 5.0, 10.0};
  const double vertical[] = {0.30172, 0.49346, 0.71379, 0.81061};
  const double horizontal[] = {0.05643, 0.16064, 0.38763, 0.55500};
  std::printf("\nCantilever under a dead tip load: tip deflection / L against the elastica (Mattiasson 1981)\n");
  std::printf("%8s %8s %10s %10s %9s %10s %10s %9s %6s\n", "faces", "PL^2/EI", "vertical", "reference", "error",
              "horizontal", "reference", "error", "iters");
  double worst_vertical = 0.0, worst_horizontal = 0.0;
  for (int nx : {8, 16}) {
    const Strip strip = make_strip(nx, 2, kLength, kWidth);
    auto model = ShellModel::build(strip.mesh, Material{kYoung, 0.0, kThickness, 0.0}).value();
    NonlinearSolver solver(model, std::make_shared<FactorCache>());
    DeformationRequest request;
    for (int j = 0; j < strip.ny; ++j) {
      for (double t : {0.0, 0.5, 1.0}) {
        request.limit_constraints.push_back({strip.at(0.0, (j + t) / strip.ny), Vec3::Zero(), Vec3::Zero(), Vec3::Zero()});
      }
    }
    // The tip load as a line load: 2-point Gauss on each face edge (exact for the cubic basis).
    const double g = 0.5 / std::sqrt(3.0);
    std::vector<SurfacePoint> load_points;
    for (int j = 0; j < strip.ny; ++j) {
      for (double t : {0.5 - g, 0.5 + g}) load_points.push_back(strip.at(1.0, (j + t) / strip.ny));
    }
    Eigen::VectorXd u = Eigen::VectorXd::Zero(model->num_dofs());
    for (size_t k = 0; k < 4; ++k) {
      const double p = loads[k] * ei / (kLength * kLength);
      request.surface_forces.clear();
      for (const SurfacePoint& point : load_points) {
        request.surface_forces.push_back({point, Vec3(0.0, 0.0, -p / static_cast<double>(load_points.size()))});
      }
      auto solution = solver.solve(request);  // each load from rest: the solver chooses its steps
      ASSERT_TRUE(solution.ok()) << solution.error().message;
      EXPECT_LT(solution->stats.residual, 1e-8);
      const Vec3 tip = limit_displacement(*model, solution->displacement, strip.at(1.0, 0.5));
      const double v = -tip.z() / kLength, h = -tip.x() / kLength;
      std::printf("%5dx%-2d %8.0f %10.5f %10.5f %8.3f%% %10.5f %10.5f %8.3f%% %6d\n", nx, strip.ny, loads[k], v,
                  vertical[k], 100 * (v / vertical[k] - 1), h, horizontal[k], 100 * (h / horizontal[k] - 1),
                  solution->stats.iterations);
      if (nx == 16) {
        worst_vertical = std::max(worst_vertical, std::abs(v / vertical[k] - 1));
        worst_horizontal = std::max(worst_horizontal, std::abs(h / horizontal[k] - 1));
      }
    }
  }
  EXPECT_LT(worst_vertical, 2e-4);  // the reference has five digits
  EXPECT_LT(worst_horizontal, 3e-4);
}

// A closed sphere under internal pressure (a follower load: it acts on the deformed area along
// the deformed normal) expands uniformly; the membrane solution of St. Venant-Kirchhoff for the
// stretch lambda is p = E t (lambda^2 - 1) / ((1 - nu) lambda R) (bending adds ~ t^2 / R^2). A dead
// load p on the reference surface would give p = E t (lambda^2 - 1) lambda / ((1 - nu) R) instead.
TEST(NonlinearReference, InflatedSphereFollowsTheMembraneSolution) {
  constexpr double kYoung = 1.0e6, kNu = 0.3, kThickness = 0.002;
  auto refined = MeshRefinement::create(test::load_asset_mesh("catmark_cube.obj"), 3).value();
  ControlMesh sphere = refined.fine();
  for (Vec3& x : sphere.positions()) x = x.normalized();
  auto model = ShellModel::build(sphere, Material{kYoung, kNu, kThickness, 0.0}).value();
  // Mean radius of the limit surface (the projected control net's limit is nearly a sphere).
  auto mean_radius = [&](const Eigen::VectorXd& u) {
    double sum = 0.0, area = 0.0;
    LimitStencil st;
    for (const QuadraturePoint& q : model->quadrature()) {
      model->evaluator().stencil(q.point, st);
      Vec3 x = Vec3::Zero();
      for (size_t k = 0; k < st.size(); ++k) {
        x += st.position[k] * (sphere.positions()[static_cast<size_t>(st.indices[k])] + u.segment<3>(3 * st.indices[k]));
      }
      sum += q.weight * x.norm();
      area += q.weight;
    }
    return sum / area;
  };
  const double radius = mean_radius(Eigen::VectorXd::Zero(model->num_dofs()));
  // Rigid motions held without restraining the expansion: the control points on the axes may move
  // only along their axis.
  DeformationRequest request;
  auto on_axis = [&](const Vec3& axis) {
    for (int32_t v = 0; v < sphere.num_vertices(); ++v) {
      if ((sphere.positions()[static_cast<size_t>(v)] - axis).norm() < 1e-9) return v;
    }
    ADD_FAILURE() << "no control point on the axis";
    return 0;
  };
  request.vertex_constraints.push_back({on_axis(Vec3(1, 0, 0)), kAxisY | kAxisZ, Vec3::Zero()});
  request.vertex_constraints.push_back({on_axis(Vec3(-1, 0, 0)), kAxisY | kAxisZ, Vec3::Zero()});
  request.vertex_constraints.push_back({on_axis(Vec3(0, 1, 0)), kAxisX | kAxisZ, Vec3::Zero()});
  NonlinearSolver solver(model, std::make_shared<FactorCache>());
  std::printf("\nInflated sphere (follower pressure), R = %.4f: stretch against the membrane solution\n", radius);
  std::printf("%10s %10s %10s %9s %10s\n", "stretch", "computed", "error", "dead load", "iters");
  for (double stretch : {1.01, 1.1, 1.3}) {
    request.pressure = kYoung * kThickness * (stretch * stretch - 1.0) / ((1.0 - kNu) * stretch * radius);
    auto solution = solver.solve(request);
    ASSERT_TRUE(solution.ok()) << solution.error().message;
    EXPECT_LT(solution->stats.residual, 1e-8);
    const double computed = mean_radius(solution->displacement) / radius;
    // The stretch a dead load of the same p would give (for the record: the follower matters).
    double dead = 1.0;
    for (int i = 0; i < 50; ++i) {
      dead = std::sqrt(1.0 + request.pressure * (1.0 - kNu) * radius / (kYoung * kThickness * dead));
    }
    std::printf("%10.3f %10.5f %8.3f%% %9.5f %10d\n", stretch, computed, 100 * (computed - stretch) / (stretch - 1.0),
                dead, solution->stats.iterations);
    EXPECT_NEAR(computed - 1.0, stretch - 1.0, 0.01 * (stretch - 1.0));
  }
}

}  // namespace
}  // namespace softshell::engine
