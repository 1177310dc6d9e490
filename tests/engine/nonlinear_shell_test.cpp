// The nonlinear Kirchhoff-Love kernel: its first-order term is the linear model's K, its tangent
// is the derivative of its internal forces, and rigid motions of any size leave it unstrained.
#include "nonlinear_shell.h"

#include <cmath>
#include <cstdio>
#include <random>

#include <Eigen/Geometry>
#include <gtest/gtest.h>

#include "test_meshes.h"

namespace softshell::engine::internal {
namespace {

Material material() { return Material{2.0e9, 0.35, 0.002, 1000.0}; }

struct Case {
  std::string name;
  ControlMesh mesh;
};

// A flat plate, a doubly curved open shell and meshes with extraordinary vertices.
std::vector<Case> cases() {
  std::vector<Case> out;
  out.push_back({"plate", test::make_grid(6, 4, 0.6, 0.4)});
  out.push_back({"dome", test::make_grid(6, 6, 1.0, 1.0, [](double x, double y) {
                   return 0.3 * std::sin(M_PI * x) * std::sin(M_PI * y);
                 })});
  for (const char* name : {"catmark_gregory_test5.obj", "catmark_nonquads.obj"}) {
    out.push_back({name, test::load_asset_mesh(name)});
  }
  return out;
}

Eigen::VectorXd random_vector(Eigen::Index n, double scale, std::mt19937& rng) {
  std::uniform_real_distribution<double> unit(-1.0, 1.0);
  Eigen::VectorXd v(n);
  for (Eigen::Index i = 0; i < n; ++i) v[i] = scale * unit(rng);
  return v;
}

double max_abs(const Eigen::SparseMatrix<double>& k) {
  double m = 0.0;
  for (Eigen::Index i = 0; i < k.nonZeros(); ++i) m = std::max(m, std::abs(k.valuePtr()[i]));
  return m;
}

TEST(NonlinearShell, AtRestTheForcesVanishAndTheTangentIsK) {
  for (const Case& c : cases()) {
    auto model = ShellModel::build(c.mesh, material()).value();
    auto shell = NonlinearShell::build(model);
    EXPECT_EQ(shell->num_points(), model->quadrature().size());
    ShellState state;
    ASSERT_TRUE(shell->evaluate(Eigen::VectorXd::Zero(model->num_dofs()), state, true)) << c.name;
    EXPECT_EQ(state.energy, 0.0) << c.name;
    EXPECT_EQ(state.internal_force.cwiseAbs().maxCoeff(), 0.0) << c.name;

    Eigen::SparseMatrix<double> tangent;
    shell->assemble_tangent(state, 0.0, tangent);
    const Eigen::SparseMatrix<double>& k = model->stiffness();
    ASSERT_EQ(tangent.nonZeros(), k.nonZeros());
    const Eigen::SparseMatrix<double> diff = tangent - k;
    EXPECT_LT(max_abs(diff), 1e-12 * max_abs(k)) << c.name;

    std::mt19937 rng(7);
    const Eigen::MatrixXd v = Eigen::MatrixXd::NullaryExpr(model->num_dofs(), 3, [&] {
      return std::uniform_real_distribution<double>(-1.0, 1.0)(rng);
    });
    Eigen::MatrixXd kv;
    shell->tangent_product(state, 0.0, v, kv);
    const Eigen::MatrixXd expected = k * v;
    EXPECT_LT((kv - expected).norm(), 1e-12 * expected.norm()) << c.name;
  }
}

TEST(NonlinearShell, TangentIsTheDerivativeOfTheInternalForces) {
  for (const Case& c : cases()) {
    auto model = ShellModel::build(c.mesh, material()).value();
    auto shell = NonlinearShell::build(model);
    const double size = c.mesh.bounding_diagonal();
    std::mt19937 rng(3);
    for (int trial = 0; trial < 2; ++trial) {
      // A random state (large displacements, strains of a few percent) and direction.
      const Eigen::VectorXd u = random_vector(model->num_dofs(), 0.02 * size, rng);
      const Eigen::VectorXd v = random_vector(model->num_dofs(), 1.0, rng);
      ShellState state, plus, minus;
      ASSERT_TRUE(shell->evaluate(u, state, true)) << c.name;
      // The second trial adds a follower pressure whose forces are as large as the internal ones.
      const double pressure = trial == 0 ? 0.0 : state.internal_force.norm() / state.pressure_force.norm();
      Eigen::MatrixXd jv;
      shell->tangent_product(state, pressure, v, jv);
      const double h = 1e-6 * size;
      ASSERT_TRUE(shell->evaluate(u + h * v, plus, true));
      ASSERT_TRUE(shell->evaluate(u - h * v, minus, true));
      const Eigen::VectorXd fd = ((plus.internal_force - pressure * plus.pressure_force) -
                                  (minus.internal_force - pressure * minus.pressure_force)) /
                                 (2.0 * h);
      EXPECT_LT((fd - jv.col(0)).norm(), 1e-6 * jv.norm()) << c.name << " pressure " << pressure;
      // The internal forces are the gradient of the energy.
      const double energy_fd = (plus.energy - minus.energy) / (2.0 * h);
      EXPECT_NEAR(energy_fd, state.internal_force.dot(v), 1e-6 * state.internal_force.norm() * v.norm()) << c.name;
      // The assembled tangent is the same operator (its symmetric part, with a pressure).
      Eigen::SparseMatrix<double> tangent;
      shell->assemble_tangent(state, pressure, tangent);
      const Eigen::SparseMatrix<double> asym = tangent - Eigen::SparseMatrix<double>(tangent.transpose());
      EXPECT_LT(max_abs(asym), 1e-12 * max_abs(tangent)) << c.name;
      EXPECT_NEAR(v.dot(tangent * v), v.dot(jv.col(0)), 1e-10 * std::abs(v.dot(jv.col(0))) + 1e-12 * jv.norm() * v.norm())
          << c.name;
      if (pressure == 0.0) {
        const Eigen::VectorXd tv = tangent * v;
        EXPECT_LT((tv - jv.col(0)).norm(), 1e-11 * jv.norm()) << c.name;
      }
    }
  }
}

// The approximate model the solver's directions and preconditioner use: K plus the nonlinear
// remainder on the coarse rule. Its assembled tangent is the operator of its products, its
// predicted change of the forces has that tangent as derivative, and it misses the true change
// only to second order from rest (exactly nothing where the coarse rule is the model's own).
TEST(NonlinearShell, TheApproximateModelIsConsistent) {
  for (const Case& c : cases()) {
    auto model = ShellModel::build(c.mesh, material()).value();
    auto shell = NonlinearShell::build(model, 0, 4);
    ASSERT_TRUE(shell->has_jacobian_rule());
    const double size = c.mesh.bounding_diagonal();
    const auto n = model->num_dofs();
    std::mt19937 rng(5);
    const Eigen::VectorXd u = random_vector(n, 0.02 * size, rng);
    const Eigen::VectorXd v = random_vector(n, 1.0, rng);
    ShellState coarse, plus, minus;
    ASSERT_TRUE(shell->evaluate_coarse(u, coarse)) << c.name;
    Eigen::VectorXd jv;
    shell->approximate_tangent_product(coarse, 0.0, v, jv);
    Eigen::SparseMatrix<double> assembled;
    shell->assemble_approximate_tangent(coarse, 0.0, assembled);
    EXPECT_LT((assembled * v - jv).norm(), 1e-11 * jv.norm()) << c.name;
    const double h = 1e-6 * size;
    ASSERT_TRUE(shell->evaluate_coarse(u + h * v, plus));
    ASSERT_TRUE(shell->evaluate_coarse(u - h * v, minus));
    const Eigen::VectorXd fd = shell->approximate_force_change(minus, plus) / (2.0 * h);
    EXPECT_LT((fd - jv).norm(), 1e-6 * jv.norm()) << c.name;

    // From rest: f(s) - predicted(s) is O(|s|^2).
    ShellState rest, fine;
    ASSERT_TRUE(shell->evaluate_coarse(Eigen::VectorXd::Zero(n), rest));
    const Eigen::VectorXd s = random_vector(n, 1e-3 * size, rng);
    double last_miss = 0.0;
    for (double scale : {1.0, 0.5}) {
      ASSERT_TRUE(shell->evaluate_coarse(scale * s, coarse));
      ASSERT_TRUE(shell->evaluate(scale * s, fine, false));
      const Eigen::VectorXd predicted = shell->approximate_force_change(rest, coarse);
      const double miss = (fine.internal_force - predicted).norm();
      EXPECT_LT(miss, 0.1 * fine.internal_force.norm()) << c.name;
      if (scale < 1.0 && last_miss > 1e-9 * fine.internal_force.norm()) {
        EXPECT_GT(last_miss / miss, 3.0) << c.name << ": the miss is not second order";
      }
      last_miss = miss;
    }
    if (c.name == "plate" || c.name == "dome") {  // no refined cells: the coarse rule is the model's
      EXPECT_LT(last_miss, 1e-9 * fine.internal_force.norm()) << c.name;
    }
  }
}

TEST(NonlinearShell, RigidMotionsOfAnySizeAreUnstrained) {
  for (const Case& c : cases()) {
    auto model = ShellModel::build(c.mesh, material()).value();
    auto shell = NonlinearShell::build(model);
    const double size = c.mesh.bounding_diagonal();
    // Scale of forces: what K gives for a displacement of the object's size.
    std::mt19937 rng(5);
    const Eigen::VectorXd probe = random_vector(model->num_dofs(), size, rng);
    const double force_scale = (model->stiffness() * probe).norm();
    for (double degrees : {30.0, 90.0, 180.0}) {
      const Eigen::Matrix3d r = Eigen::AngleAxisd(degrees * M_PI / 180.0, Vec3(1.0, 2.0, 3.0).normalized()).toRotationMatrix();
      Eigen::VectorXd u(model->num_dofs());
      for (int32_t i = 0; i < model->num_control_points(); ++i) {
        const Vec3 x = c.mesh.positions()[static_cast<size_t>(i)];
        u.segment<3>(3 * i) = r * x - x + Vec3(0.1, -0.2, 0.3) * size;
      }
      ShellState state;
      ASSERT_TRUE(shell->evaluate(u, state, false)) << c.name;
      EXPECT_LT(state.internal_force.norm(), 1e-13 * force_scale) << c.name << " " << degrees;
      // The linear model, by contrast, strains it.
      EXPECT_GT((model->stiffness() * u).norm(), 1e-3 * force_scale) << c.name << " " << degrees;
    }
  }
}

// The early rule (Newton's first iterations evaluate the forces on it): the model's own rule with
// fewer refinement levels toward extraordinary vertices, built as the model's is (so its forces
// are those of a model built with that many levels), unstrained by rigid motions like any rule,
// and within a small fraction of the model's forces on a deformed state. None where it would not
// save a third of the points (no extraordinary vertex: the rules are the same).
TEST(NonlinearShell, TheEarlyRuleIsTheModelsWithFewerLevels) {
  for (const Case& c : cases()) {
    auto model = ShellModel::build(c.mesh, material()).value();
    auto shell = NonlinearShell::build(model, 0, 4, nullptr, 2);
    if (c.name == "plate" || c.name == "dome") {
      EXPECT_FALSE(shell->has_early_rule()) << c.name;
      continue;
    }
    ASSERT_TRUE(shell->has_early_rule()) << c.name;
    PrecomputeOptions two_levels;
    two_levels.quadrature.ev_refinement_levels = 2;
    auto reference = NonlinearShell::build(ShellModel::build(c.mesh, material(), two_levels).value());
    EXPECT_EQ(shell->num_early_points(), reference->num_points()) << c.name;
    EXPECT_LE(3 * shell->num_early_points(), 2 * shell->num_points()) << c.name;

    const double size = c.mesh.bounding_diagonal();
    const auto n = model->num_dofs();
    std::mt19937 rng(7);
    const Eigen::VectorXd u = random_vector(n, 0.01 * size, rng);
    ShellState early, fine, same;
    ASSERT_TRUE(shell->evaluate_early(u, early, false)) << c.name;
    EXPECT_TRUE(early.early);
    ASSERT_TRUE(reference->evaluate(u, same, false)) << c.name;
    EXPECT_LT((early.internal_force - same.internal_force).norm(), 1e-12 * same.internal_force.norm()) << c.name;
    EXPECT_NEAR(early.energy, same.energy, 1e-12 * same.energy) << c.name;
    ASSERT_TRUE(shell->evaluate(u, fine, false)) << c.name;
    EXPECT_FALSE(fine.early);
    const double difference = (early.internal_force - fine.internal_force).norm() / fine.internal_force.norm();
    EXPECT_LT(difference, 1e-2) << c.name;
    EXPECT_GT(difference, 0.0) << c.name << ": the early rule is the model's";
    std::printf("%-26s %zu points, early rule %zu: forces %.1e apart\n", c.name.c_str(), shell->num_points(),
                shell->num_early_points(), difference);

    // A rigid motion strains it no more than the model's rule (round-off).
    const Eigen::Matrix3d r = Eigen::AngleAxisd(1.2, Vec3(1.0, 2.0, 3.0).normalized()).toRotationMatrix();
    Eigen::VectorXd turned(n);
    for (int32_t i = 0; i < model->num_control_points(); ++i) {
      const Vec3 x = c.mesh.positions()[static_cast<size_t>(i)];
      turned.segment<3>(3 * i) = r * x - x;
    }
    ASSERT_TRUE(shell->evaluate_early(turned, early, false)) << c.name;
    EXPECT_LT(early.internal_force.norm(), 1e-13 * (model->stiffness() * turned).norm()) << c.name;
  }
  EXPECT_THROW(NonlinearShell::build(ShellModel::build(cases()[0].mesh, material()).value(), 0, 4, nullptr, 9),
               std::exception);
}

}  // namespace
}  // namespace softshell::engine::internal
