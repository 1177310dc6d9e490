#include "softshell/engine/stresses.h"

#include <gtest/gtest.h>

#include "softshell/engine/solver.h"
#include "test_meshes.h"

namespace softshell::engine {
namespace {

// A strip stretched by a prescribed end displacement is in uniform uniaxial stress E * strain.
TEST(Stresses, UniaxialTension) {
  const double length = 2.0, width = 0.5, stretch = 1e-3;
  ControlMesh mesh = test::make_grid(8, 2, length, width);
  const Material material{2.0e11, 0.3, 0.002, 7850.0};
  auto model = ShellModel::build(mesh, material).value();
  Solver solver(model, std::make_shared<FactorCache>());
  DeformationRequest request;
  for (int j = 0; j <= 2; ++j) {
    request.vertex_constraints.push_back({test::grid_index(8, 0, j), kAxisX | kAxisZ, Vec3::Zero()});
    request.vertex_constraints.push_back({test::grid_index(8, 8, j), kAxisX | kAxisZ, Vec3(stretch, 0, 0)});
  }
  request.vertex_constraints.push_back({test::grid_index(8, 0, 0), kAxisY, Vec3::Zero()});
  auto solution = solver.solve(request);
  ASSERT_TRUE(solution.ok()) << solution.error().message;
  const double sigma = material.youngs_modulus * stretch / length;
  for (const SurfacePoint& p : {SurfacePoint{3, 0, 0.5, 0.5}, SurfacePoint{9, 0, 0.1, 0.9}, SurfacePoint{15, 0, 1.0, 0.0}}) {
    StressSample s = evaluate_stress(*model, solution->displacement, p);
    EXPECT_NEAR(s.membrane_force[0], sigma * material.thickness, 1e-6 * sigma * material.thickness);
    EXPECT_NEAR(s.membrane_force[1], 0.0, 1e-6 * sigma * material.thickness);
    EXPECT_NEAR(s.membrane_force[2], 0.0, 1e-6 * sigma * material.thickness);
    EXPECT_NEAR(s.bending_moment.norm(), 0.0, 1e-9 * sigma * material.thickness);
    EXPECT_NEAR(s.von_mises_top, sigma, 1e-6 * sigma);
    EXPECT_NEAR(s.von_mises_bottom, sigma, 1e-6 * sigma);
  }
  StressSummary summary = max_stress(*model, solution->displacement, 2.5e8);
  EXPECT_NEAR(summary.max.von_mises(), sigma, 1e-6 * sigma);
  EXPECT_FALSE(summary.exceeds_yield);  // 1e8 Pa < 2.5e8 Pa
  EXPECT_TRUE(max_stress(*model, solution->displacement, 0.5e8).exceeds_yield);
}

// Pure bending: uniform curvature kappa along x gives the moment m = D kappa (nu = 0), with equal
// and opposite stresses at the two surfaces: von Mises 6 m / t^2 at both. The mesh has a ghost
// layer (BoundaryMode::kNone) so that the quadratic w = kappa x^2 / 2 lies in the spline space up
// to the edges; three columns of control points at each end prescribe its value and slope there.
TEST(Stresses, PureBendingOfAStrip) {
  const double length = 1.0, width = 0.25, t = 0.01;
  ControlMesh mesh = test::make_grid(16, 4, length, width);
  mesh.set_boundary(BoundaryMode::kNone);
  const Material material{7.0e10, 0.0, t, 2700.0};
  auto model = ShellModel::build(mesh, material).value();
  Solver solver(model, std::make_shared<FactorCache>());
  const double kappa = 0.01, h = length / 16;
  DeformationRequest request;
  for (int j = 0; j <= 4; ++j) {
    for (int i = 0; i <= 16; ++i) {
      const int32_t index = test::grid_index(16, i, j);
      request.vertex_constraints.push_back({index, kAxisX | kAxisY, Vec3::Zero()});
      if (i <= 2 || i >= 14) {
        const double x = length * i / 16;  // B-spline control values of kappa x^2 / 2
        request.vertex_constraints.push_back({index, kAxisZ, Vec3(0, 0, 0.5 * kappa * (x * x - h * h / 3.0))});
      }
    }
  }
  auto solution = solver.solve(request);
  ASSERT_TRUE(solution.ok()) << solution.error().message;
  const double moment = material.youngs_modulus * t * t * t / 12.0 * kappa;
  for (const SurfacePoint& p : {SurfacePoint{24, 0, 0.5, 0.5}, SurfacePoint{35, 0, 0.2, 0.9}}) {
    StressSample s = evaluate_stress(*model, solution->displacement, p);
    EXPECT_NEAR(std::abs(s.bending_moment[0]), moment, 1e-6 * moment);
    EXPECT_NEAR(s.bending_moment[1], 0.0, 1e-6 * moment);
    EXPECT_NEAR(s.von_mises_top, 6.0 * moment / (t * t), 1e-6 * 6.0 * moment / (t * t));
    EXPECT_NEAR(s.von_mises_bottom, s.von_mises_top, 1e-6 * s.von_mises_top);
  }
}

TEST(Stresses, RejectsBadInput) {
  auto model = ShellModel::build(test::make_grid(2, 2), Material{}).value();
  EXPECT_THROW(evaluate_stress(*model, Eigen::VectorXd::Zero(3), {0, 0, 0.5, 0.5}), Exception);
  EXPECT_THROW(evaluate_stress(*model, Eigen::VectorXd::Zero(model->num_dofs()), {9, 0, 0.5, 0.5}), Exception);
}

}  // namespace
}  // namespace softshell::engine
