// The physics checked against analytic and published reference solutions (not against itself).
// Each test prints its convergence table; the README's accuracy tables come from these numbers.
#include <cstdio>

#include <gtest/gtest.h>

#include "shell_benchmarks.h"
#include "softshell/engine/solver.h"

namespace softshell::engine {
namespace {

// Plate: a = 1, t = 0.01, E = 1e7, nu = 0.3 (Kirchhoff: only D matters).
constexpr double kSide = 1.0, kThickness = 0.01, kYoung = 1.0e7, kNu = 0.3;
double plate_d() { return kYoung * kThickness * kThickness * kThickness / (12.0 * (1.0 - kNu * kNu)); }

double limit_w(const ShellModel& model, const Eigen::VectorXd& u, const SurfacePoint& p) {
  LimitStencil st = model.evaluator().stencil(p);
  double w = 0.0;
  for (size_t k = 0; k < st.size(); ++k) w += st.position[k] * u[3 * st.indices[k] + 2];
  return w;
}

enum class Load { kUniform, kCentre };

// Centre deflection coefficient w D / (q a^4) or w D / (P a^2).
double plate_coefficient(const test::Plate& plate, const std::vector<VertexConstraint>& supports,
                         const std::vector<LimitConstraint>& limit, Load load) {
  auto model = ShellModel::build(plate.mesh, Material{kYoung, kNu, kThickness, 0.0}).value();
  Solver solver(model, std::make_shared<FactorCache>());
  DeformationRequest request;
  request.vertex_constraints = supports;
  request.limit_constraints = limit;
  const double q = 1.0, p = 1.0;
  if (load == Load::kUniform) {
    request.surface_load = Vec3(0, 0, -q);
  } else {
    request.surface_forces.push_back({plate.centre(), Vec3(0, 0, -p)});
  }
  auto solution = solver.solve(request);
  EXPECT_TRUE(solution.ok()) << solution.error().message;
  if (!solution.ok()) return 0.0;
  const double w = -limit_w(*model, solution->displacement, plate.centre());
  return load == Load::kUniform ? w * plate_d() / (q * std::pow(kSide, 4)) : w * plate_d() / (p * kSide * kSide);
}

TEST(ReferenceSolutions, SimplySupportedSquarePlateUniformLoad) {
  std::printf("\nSimply supported square plate, uniform load: w D / (q a^4), reference 0.00406 (0.004062)\n");
  std::printf("%8s %10s %12s %10s\n", "faces", "controls", "coefficient", "error");
  double last = 0.0;
  for (int n : {4, 8, 16, 32}) {
    test::Plate plate = test::make_plate(n, kSide);
    last = plate_coefficient(plate, test::simply_supported(plate), {}, Load::kUniform);
    std::printf("%5dx%-3d %10d %12.6f %9.3f%%\n", n, n, plate.mesh.num_vertices(), last, 100 * (last / 0.00406 - 1));
  }
  EXPECT_NEAR(last, 0.00406, 0.005 * 0.00406);
}

TEST(ReferenceSolutions, SimplySupportedSquarePlateCentreLoad) {
  std::printf("\nSimply supported square plate, centre point load: w D / (P a^2), reference 0.01160\n");
  std::printf("%8s %10s %12s %10s\n", "faces", "controls", "coefficient", "error");
  double last = 0.0;
  for (int n : {4, 8, 16, 32}) {
    test::Plate plate = test::make_plate(n, kSide);
    last = plate_coefficient(plate, test::simply_supported(plate), {}, Load::kCentre);
    std::printf("%5dx%-3d %10d %12.6f %9.3f%%\n", n, n, plate.mesh.num_vertices(), last, 100 * (last / 0.0116 - 1));
  }
  EXPECT_NEAR(last, 0.0116, 0.01 * 0.0116);
}

// Clamped plate two ways:
//  (a) OpenSubdiv's boundary rule (edge_and_corner) with the two outer rows of control points
//      fixed. The rule forces w,nn = 0 at the edge, which a clamped plate does not have, so the
//      error falls only slowly.
//  (b) boundary "none" with a ghost ring of faces: the plate is a full B-spline space up to its
//      edges and the clamp (w = 0, dw/dn = 0 along every edge) is imposed exactly with limit
//      constraints (position and tangents) at three points per face edge.
std::vector<LimitConstraint> clamp_edges(const test::Plate& plate) {
  std::vector<LimitConstraint> out;
  for (int k = 0; k < plate.n; ++k) {
    for (double s : {0.0, 0.5, 1.0}) {
      const double x = (k + s) / plate.n;
      for (SurfacePoint p : {plate.at(x, 0.0), plate.at(x, 1.0), plate.at(0.0, x), plate.at(1.0, x)}) {
        out.push_back({p, Vec3::Zero(), Vec3::Zero(), Vec3::Zero()});
      }
    }
  }
  return out;
}

TEST(ReferenceSolutions, ClampedSquarePlate) {
  std::printf("\nClamped square plate: w D / (q a^4), reference 0.00126;  w D / (P a^2), reference 0.00560\n");
  std::printf("%8s %14s %9s %14s %9s %14s %9s\n", "faces", "(a) rows, q", "error", "(b) ghost, q", "error",
              "(b) ghost, P", "error");
  double ghost_uniform = 0.0, ghost_point = 0.0, rows_uniform = 0.0;
  for (int n : {4, 8, 16, 32}) {
    test::Plate rows = test::make_plate(n, kSide);
    std::vector<VertexConstraint> clamp = test::in_plane_fixed(rows);
    for (int j = 0; j <= n; ++j) {
      for (int i = 0; i <= n; ++i) {
        if (i <= 1 || j <= 1 || i >= n - 1 || j >= n - 1) clamp.push_back({rows.index(i, j), kAxisZ, Vec3::Zero()});
      }
    }
    rows_uniform = plate_coefficient(rows, clamp, {}, Load::kUniform);
    test::Plate ghost = test::make_plate(n, kSide, true);
    ghost_uniform = plate_coefficient(ghost, test::in_plane_fixed(ghost), clamp_edges(ghost), Load::kUniform);
    ghost_point = plate_coefficient(ghost, test::in_plane_fixed(ghost), clamp_edges(ghost), Load::kCentre);
    std::printf("%5dx%-3d %14.6f %8.2f%% %14.6f %8.3f%% %14.6f %8.3f%%\n", n, n, rows_uniform,
                100 * (rows_uniform / 0.00126 - 1), ghost_uniform, 100 * (ghost_uniform / 0.00126 - 1), ghost_point,
                100 * (ghost_point / 0.0056 - 1));
  }
  // The ghost-layer clamp converges to the reference; the boundary-rule clamp stays visibly stiff.
  EXPECT_NEAR(ghost_uniform, 0.00126, 0.005 * 0.00126);
  EXPECT_NEAR(ghost_point, 0.0056, 0.01 * 0.0056);
  EXPECT_LT(std::abs(ghost_uniform / 0.00126 - 1), std::abs(rows_uniform / 0.00126 - 1));
}

TEST(ReferenceSolutions, ScordelisLoRoof) {
  std::printf("\nScordelis-Lo roof: vertical displacement at the middle of a free edge, reference %.4f (KL)\n",
              test::ScordelisLo::kReference);
  std::printf("%8s %10s %12s %10s\n", "faces", "controls", "u_z", "error");
  double last = 0.0;
  for (int n : {4, 8, 16, 24, 32}) {
    test::ScordelisLo roof = test::make_scordelis_lo(n, n);
    auto model = ShellModel::build(roof.mesh, test::ScordelisLo::material()).value();
    Solver solver(model, std::make_shared<FactorCache>());
    DeformationRequest request;
    request.vertex_constraints = roof.supports();
    request.surface_load = Vec3(0, 0, -90.0);
    auto solution = solver.solve(request);
    ASSERT_TRUE(solution.ok()) << solution.error().message;
    last = -limit_w(*model, solution->displacement, roof.free_edge_midpoint());
    std::printf("%5dx%-3d %10d %12.6f %9.3f%%\n", n, n, roof.mesh.num_vertices(), last,
                100 * (last / test::ScordelisLo::kReference - 1));
  }
  EXPECT_NEAR(last, test::ScordelisLo::kReference, 0.01 * test::ScordelisLo::kReference);
}

}  // namespace
}  // namespace softshell::engine
