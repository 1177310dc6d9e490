// The nonlinear model against published large-deflection solutions (not against itself). Each
// test prints its convergence table.
#include <cmath>
#include <cstdio>

#include <Eigen/Geometry>
#include <gtest/gtest.h>

#include "limit_displacement.h"
#include "shell_benchmarks.h"
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

using test::limit_displacement;

// Cantilever strip (nu = 0, so it bends as a beam), clamped at x = 0, a dead vertical load P at
// the free end spread evenly along it. Mattiasson (1981), elliptic-integral solution of the
// elastica: tip deflection / L, vertical and horizontal, for P L^2 / EI = 1, 2, 5, 10.
TEST(NonlinearReference, LargeDeflectionCantileverFollowsTheElastica) {
  constexpr double kLength = 1.0, kWidth = 0.1, kThickness = 0.01, kYoung = 1.0e7;
  const double ei = kYoung * kWidth * kThickness * kThickness * kThickness / 12.0;
  const auto& reference = test::kMattiassonCantilever;
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
    for (const test::ElasticaPoint& ref : reference) {
      const double p = ref.load * ei / (kLength * kLength);
      request.surface_forces.clear();
      for (const SurfacePoint& point : load_points) {
        request.surface_forces.push_back({point, Vec3(0.0, 0.0, -p / static_cast<double>(load_points.size()))});
      }
      auto solution = solver.solve(request);  // each load from rest: the solver chooses its steps
      ASSERT_TRUE(solution.ok()) << solution.error().message;
      EXPECT_LT(solution->stats.residual, 1e-8);
      const Vec3 tip = limit_displacement(*model, solution->displacement, strip.at(1.0, 0.5));
      const double v = -tip.z() / kLength, h = -tip.x() / kLength;
      std::printf("%5dx%-2d %8.0f %10.5f %10.5f %8.3f%% %10.5f %10.5f %8.3f%% %6d\n", nx, strip.ny, ref.load, v,
                  ref.vertical, 100 * (v / ref.vertical - 1), h, ref.horizontal, 100 * (h / ref.horizontal - 1),
                  solution->stats.iterations);
      if (nx == 16) {
        worst_vertical = std::max(worst_vertical, std::abs(v / ref.vertical - 1));
        worst_horizontal = std::max(worst_horizontal, std::abs(h / ref.horizontal - 1));
      }
    }
  }
  EXPECT_LT(worst_vertical, 2e-4);  // the reference has five digits
  EXPECT_LT(worst_horizontal, 3e-4);
}

// The cantilever rolled up by an end moment (Sze, Liu and Lo 2004, "Popular benchmark problems
// for geometric nonlinear analysis of shells", the cantilever subjected to end moment): L = 12,
// b = 1, t = 0.1, E = 1.2e6, nu = 0, so EI = 100 and the largest moment 50 pi / 3 turns the tip by
// M L / EI = 2 pi: the strip closes into a circle. Exact: constant curvature theta / L, tip at
// (L sin(theta) / theta, -L (1 - cos(theta)) / theta), strain energy EI theta^2 / (2 L).
//
// The end rotation is prescribed instead of the moment (a moment that turns with the end is not
// a load the API has): the tip's u tangents are turned by theta (Lagrange rows on their limit
// stencils), its position is free. The reaction of such rows has zero resultant force (the
// derivative weights sum to zero), so the strip carries a pure end moment; the strain energy
// checks its size. The shell is not quite the inextensible elastica: its bending measure is the
// change of the covariant curvature a_11 . n, which grows with the stretch squared, so the strip
// shortens a little and the energy is lower by about delta = (t theta / L)^2 / 12 (the stretch
// lambda^2 = 1 - delta balancing E t (lambda^2 - 1) against the bending; 2.3e-4 at 2 pi); the
// energy is checked against that. Dragged in steps of 15 degrees, each from the previous answer: at theta = pi and
// 2 pi the prescribed tangent alone (-A1, A1) does not say which way the end went.
TEST(NonlinearReference, CantileverUnderAnEndMomentRollsIntoACircle) {
  constexpr double kLength = 12.0, kWidth = 1.0, kThickness = 0.1, kYoung = 1.2e6;
  const double ei = kYoung * kWidth * kThickness * kThickness * kThickness / 12.0;
  std::printf("\nCantilever under an end moment (Sze, Liu, Lo 2004): tip displacement / L against the circle\n");
  std::printf("%6s %6s %10s %10s %10s %10s %9s %9s %9s %8s %7s\n", "faces", "turn", "-u/L", "exact", "-w/L", "exact",
              "tip error", "energy", "-delta", "iters", "steps");
  double worst_tip = 0.0, worst_energy = 0.0;
  for (int nx : {16, 32}) {
    const Strip strip = make_strip(nx, 2, kLength, kWidth);
    auto model = ShellModel::build(strip.mesh, Material{kYoung, 0.0, kThickness, 0.0}).value();
    NonlinearSolver solver(model, std::make_shared<FactorCache>());
    DeformationRequest request;
    std::vector<SurfacePoint> tip_points;
    for (int j = 0; j < strip.ny; ++j) {
      for (double t : {0.0, 0.5, 1.0}) {
        request.limit_constraints.push_back({strip.at(0.0, (j + t) / strip.ny), Vec3::Zero(), Vec3::Zero(), Vec3::Zero()});
        if (j == 0 || t > 0.0) tip_points.push_back(strip.at(1.0, (j + t) / strip.ny));
      }
    }
    Eigen::VectorXd u = Eigen::VectorXd::Zero(model->num_dofs());
    int iterations = 0, steps = 0;
    for (int degrees = 15; degrees <= 360; degrees += 15) {
      const double theta = degrees * M_PI / 180.0;
      const Eigen::Matrix3d turn = Eigen::AngleAxisd(theta, Vec3::UnitY()).toRotationMatrix();
      request.lagrange_constraints = test::turned_tangents(model->evaluator(), tip_points, turn);
      auto solution = solver.solve(request, u);
      ASSERT_TRUE(solution.ok()) << nx << " faces, " << degrees << " degrees: " << solution.error().message;
      EXPECT_LT(solution->stats.residual, 1e-8);
      u = solution->displacement;
      iterations += solution->stats.iterations;
      steps += solution->stats.load_steps;
      if (degrees % 90 != 0) continue;
      const Vec3 tip = limit_displacement(*model, u, strip.at(1.0, 0.5)) / kLength;
      const Vec3 exact(std::sin(theta) / theta - 1.0, 0.0, -(1.0 - std::cos(theta)) / theta);
      const double energy = solution->stats.strain_energy / (ei * theta * theta / (2.0 * kLength)) - 1.0;
      const double tip_error = (tip - exact).norm();  // of L
      const double delta = std::pow(kThickness * theta / kLength, 2) / 12.0;
      std::printf("%6d %5d%s %10.5f %10.5f %10.5f %10.5f %9.1e %8.4f%% %8.4f%% %8d %7d\n", nx, degrees, "\u00b0", -tip.x(),
                  -exact.x(), -tip.z(), -exact.z(), tip_error, 100 * energy, -100 * delta, iterations, steps);
      iterations = steps = 0;
      if (nx == 32) {
        worst_tip = std::max(worst_tip, tip_error);
        worst_energy = std::max(worst_energy, std::abs(energy + delta));
      }
    }
  }
  EXPECT_LT(worst_tip, 1e-4);     // of L
  EXPECT_LT(worst_energy, 2e-5);  // against the stretch-corrected energy
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
