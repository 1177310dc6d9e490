// Stresses of nonlinear results: exact for homogeneous stretches, zero for rigid motions, the
// linear model's in the limit of small displacements.
#include "softshell/engine/nonlinear_stresses.h"

#include <cmath>

#include <Eigen/Geometry>
#include <gtest/gtest.h>

#include "softshell/engine/nonlinear_solver.h"
#include "softshell/engine/solver.h"
#include "softshell/engine/stresses.h"
#include "test_meshes.h"

namespace softshell::engine {
namespace {

constexpr double kYoung = 2.0e9, kNu = 0.3, kThickness = 0.002;
Material material() { return Material{kYoung, kNu, kThickness, 1000.0}; }

TEST(NonlinearStresses, UniformStretchGivesTheStVenantKirchhoffStresses) {
  const ControlMesh plate = test::make_grid(6, 4, 0.6, 0.4);
  auto model = ShellModel::build(plate, material()).value();
  for (double stretch : {1.001, 1.2, 1.5}) {
    // Every control point moved by (stretch - 1) x along x: the limit surface is stretched
    // uniformly (Catmull-Clark reproduces affine maps), with no lateral strain.
    Eigen::VectorXd u = Eigen::VectorXd::Zero(model->num_dofs());
    for (int32_t v = 0; v < plate.num_vertices(); ++v) u[3 * v] = (stretch - 1.0) * plate.positions()[static_cast<size_t>(v)].x();
    const NonlinearStressSample s = evaluate_nonlinear_stress(*model, u, SurfacePoint{9, 0, 0.3, 0.6});
    const double e11 = 0.5 * (stretch * stretch - 1.0);
    const double c = kYoung * kThickness / (1.0 - kNu * kNu);
    EXPECT_NEAR(s.green_lagrange_strain[0], e11, 1e-12 * e11);
    EXPECT_NEAR(s.green_lagrange_strain[1], 0.0, 1e-12 * e11);
    EXPECT_NEAR(s.pk2_membrane_force[0], c * e11, 1e-10 * c * e11);
    EXPECT_NEAR(s.pk2_membrane_force[1], c * kNu * e11, 1e-10 * c * e11);
    EXPECT_NEAR(s.pk2_membrane_force[2], 0.0, 1e-10 * c * e11);
    // Cauchy = F S F^T / J with F = diag(stretch, 1), J = stretch.
    EXPECT_NEAR(s.cauchy_membrane_force[0], stretch * c * e11, 1e-10 * c * e11);
    EXPECT_NEAR(s.cauchy_membrane_force[1], c * kNu * e11 / stretch, 1e-10 * c * e11);
    EXPECT_NEAR(s.pk2_bending_moment.norm(), 0.0, 1e-10 * c * e11 * kThickness);
    EXPECT_NEAR(s.von_mises_top, s.von_mises_bottom, 1e-9 * s.von_mises_top);
  }
}

TEST(NonlinearStresses, RigidMotionsAreStressFree) {
  const ControlMesh helmet = test::load_asset_mesh("catmark_helmet.obj");
  auto model = ShellModel::build(helmet, material()).value();
  const Eigen::Matrix3d r = Eigen::AngleAxisd(2.0, Vec3(1.0, -2.0, 0.5).normalized()).toRotationMatrix();
  Eigen::VectorXd u(model->num_dofs());
  for (int32_t v = 0; v < helmet.num_vertices(); ++v) {
    const Vec3 x = helmet.positions()[static_cast<size_t>(v)];
    u.segment<3>(3 * v) = r * x - x + Vec3(0.3, 0.1, -0.2);
  }
  // A stress of a strain of 1e-12 would be E * 1e-12.
  EXPECT_LT(nonlinear_max_stress(*model, u, 1e9).max.von_mises(), 1e-12 * kYoung);
  EXPECT_GT(max_stress(*model, u, 1e9).max.von_mises(), 1e-3 * kYoung);  // what the linear model says
}

TEST(NonlinearStresses, SmallDisplacementsGiveTheLinearStresses) {
  const ControlMesh grid = test::make_grid(8, 4, 0.4, 0.2, [](double x, double y) { return 0.05 * std::sin(3 * x + y); });
  auto model = ShellModel::build(grid, material()).value();
  auto cache = std::make_shared<FactorCache>();
  DeformationRequest request;
  for (int j = 0; j <= 4; ++j) {
    for (int i = 0; i <= 1; ++i) request.vertex_constraints.push_back({test::grid_index(8, i, j), kAxisAll, Vec3::Zero()});
  }
  const SurfacePoint probe{8 + 2, 0, 0.4, 0.7};
  std::vector<double> difference;
  for (double load : {1e-2, 1e-3}) {
    request.forces = {{test::grid_index(8, 8, 2), Vec3(0.0, 0.2 * load, -load)}};
    auto lin = Solver(model, cache).solve(request);
    auto non = NonlinearSolver(model, cache).solve(request);
    ASSERT_TRUE(lin.ok() && non.ok());
    const StressSample ls = evaluate_stress(*model, lin->displacement, probe);
    const NonlinearStressSample ns = evaluate_nonlinear_stress(*model, non->displacement, probe);
    const double scale = ls.membrane_force.norm() + ls.bending_moment.norm() / kThickness;
    difference.push_back(((ns.pk2_membrane_force - ls.membrane_force).norm() +
                          (ns.pk2_bending_moment - ls.bending_moment).norm() / kThickness) /
                         scale);
    EXPECT_NEAR(ns.von_mises(), ls.von_mises(), 0.05 * ls.von_mises());
  }
  EXPECT_LT(difference[0], 0.05);
  EXPECT_NEAR(difference[1] / difference[0], 0.1, 0.03);  // the difference is first order in the load
}

}  // namespace
}  // namespace softshell::engine
