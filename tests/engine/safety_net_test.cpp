// The final check of every answer: a corrupted fast path is caught and answered by the robust
// path; a pin block is zeroed only for true zero-energy motions; residuals at round-off of the
// geometry are not mistaken for contradictions.
#include <gtest/gtest.h>

#include "factorization.h"
#include "problem.h"
#include "scoped_knob.h"
#include "shell_benchmarks.h"
#include "softshell/engine/solver.h"
#include "softshell/interaction.h"
#include "softshell/tessellation.h"
#include "solver_testing.h"
#include "test_meshes.h"

namespace softshell::engine {
namespace {

double relative_difference(const Eigen::VectorXd& a, const Eigen::VectorXd& b) {
  return (a - b).norm() / std::max(a.norm(), 1e-300);
}

// A plate held by limit constraints (pins and Schur rows on the fast path) under a point load.
struct HeldPlate {
  test::Plate plate = test::make_plate(8, 1.0);
  std::shared_ptr<const ShellModel> model = ShellModel::build(plate.mesh, Material{7e10, 0.3, 1e-3, 0.0}).value();
  DeformationRequest request() const {
    DeformationRequest r;
    for (auto [s, t] : {std::pair{0.0, 0.0}, std::pair{1.0, 0.0}, std::pair{0.0, 1.0}, std::pair{1.0, 1.0}}) {
      r.limit_constraints.push_back({plate.at(s, t), Vec3::Zero(), {}, {}});
    }
    r.surface_forces.push_back({plate.at(0.4, 0.6), Vec3(0.0, 0.0, -1.0)});
    return r;
  }
};

TEST(SafetyNet, CorruptedFastPathIsCaughtAndAnsweredByTheRobustPath) {
  HeldPlate held;
  Solver solver(held.model, std::make_shared<FactorCache>());
  auto reference = solver.solve_with_fallback(held.request());
  ASSERT_TRUE(reference.ok()) << reference.error().message;
  auto clean = solver.solve(held.request());
  ASSERT_TRUE(clean.ok());
  EXPECT_EQ(clean->stats.path, SolvePath::kCachedFactor);
  EXPECT_FALSE(clean->stats.fast_path_rejected);
  EXPECT_LE(clean->stats.check_ratio, 1.0);
  EXPECT_LT(relative_difference(clean->displacement, reference->displacement), 1e-10);

  // Three ways the fast path could go wrong: a wrong value on one DOF (one part in a million of
  // the answer), an answer scaled by 1 + 1e-6 (as a wrongly zeroed block would give), NaN.
  for (internal::FastPathCorruption corrupt : std::initializer_list<internal::FastPathCorruption>{
           [](Eigen::VectorXd& u) { u[3 * 40 + 2] += 1e-6 * u.cwiseAbs().maxCoeff(); },
           [](Eigen::VectorXd& u) { u *= 1.0 + 1e-6; },
           [](Eigen::VectorXd& u) { u[7] = std::numeric_limits<double>::quiet_NaN(); }}) {
    const test::ScopedKnob<internal::FastPathCorruption> installed(internal::g_corrupt_fast_path, corrupt);
    auto caught = solver.solve(held.request());
    ASSERT_TRUE(caught.ok()) << caught.error().message;
    EXPECT_EQ(caught->stats.path, SolvePath::kFallback);
    EXPECT_TRUE(caught->stats.fast_path_rejected);
    EXPECT_LE(caught->stats.check_ratio, 1.0);
    EXPECT_LT(relative_difference(caught->displacement, reference->displacement), 1e-10);
  }
}

// The pins' block of the Schur complement is set to zero only when the pinned motions really are
// zero-energy: with a motion that is not (a bending mode), it is kept as computed.
TEST(SafetyNet, PinBlockIsZeroedOnlyForZeroEnergyMotions) {
  HeldPlate held;
  const internal::Pins pins = internal::choose_pins(*held.model, {});
  ASSERT_EQ(pins.dofs.size(), 6u);
  const internal::Factorization exact(*held.model, {}, pins.dofs, pins.motions);
  EXPECT_TRUE(exact.pin_block_zeroed());
  EXPECT_LT(exact.pin_motion_residual(), 1e-13);
  EXPECT_EQ(exact.pin_block().cwiseAbs().maxCoeff(), 0.0);
  // A bending field w = x^2 added to the first motion: no longer zero-energy.
  Eigen::MatrixXd bent = pins.motions;
  for (int32_t v = 0; v < held.plate.mesh.num_vertices(); ++v) {
    const double x = held.plate.mesh.positions()[static_cast<size_t>(v)].x();
    bent(3 * v + 2, 0) += 1e-3 * x * x;
  }
  const internal::Factorization fake(*held.model, {}, pins.dofs, bent);
  EXPECT_FALSE(fake.pin_block_zeroed());
  EXPECT_GT(fake.pin_motion_residual(), 1e-6);
}

// The righthanded mesh (the README's Horse-scale mesh) on a floor that holds it where it is
// shown: the targets are differences of two evaluations of the same points (~1e-13), and they
// contradict each other only at that round-off. That is an answer, not a contradiction; and so
// is one point held twice at targets 1e-15 of the object's size apart. A millionth of it apart
// is a contradiction.
TEST(SafetyNet, RoundOffOfTheGeometryIsNotAContradiction) {
  const ControlMesh mesh = test::load_asset_mesh("catmark_righthanded.obj");
  const double size = mesh.bounding_diagonal();
  auto model = ShellModel::build(mesh, Material{1e6, 0.45, 0.01, 1100.0}).value();
  const Tessellation surface = Tessellation::create(model->evaluator(), 3).value();
  double floor_y = std::numeric_limits<double>::infinity();
  for (const Vec3& p : surface.vertices()) floor_y = std::min(floor_y, p.y());
  FloorContact floor;
  for (double tolerance : {0.01, 0.03, 0.06, 0.12}) {
    floor = floor_contact(surface, Plane{Vec3(0.0, floor_y, 0.0), Vec3::UnitY()}, {tolerance * size}).value();
    if (floor.fixes_rigid_motion) break;
  }
  ASSERT_TRUE(floor.fixes_rigid_motion);
  Solver solver(model, std::make_shared<FactorCache>());
  DeformationRequest rest;
  floor.add_to(rest);
  for (int repeat = 0; repeat < 3; ++repeat) {  // uncached, caching, cached
    auto solution = solver.solve(rest);
    ASSERT_TRUE(solution.ok()) << solution.error().message;
    EXPECT_LT(solution->displacement.cwiseAbs().maxCoeff(), 1e-9 * size);
  }
  ASSERT_TRUE(solver.solve_with_fallback(rest).ok());

  for (double apart : {1e-15, 1e-6}) {
    DeformationRequest twice = rest;
    const SurfacePoint p = floor.points.front();
    twice.limit_constraints.push_back({p, floor.limit_constraints.front().displacement + Vec3(0.0, apart * size, 0.0), {}, {}});
    for (bool robust : {false, true}) {
      auto r = robust ? solver.solve_with_fallback(twice) : solver.solve(twice);
      if (apart < 1e-13) {
        EXPECT_TRUE(r.ok()) << r.error().message;
      } else {
        ASSERT_FALSE(r.ok());
        EXPECT_NE(r.error().message.find("contradict"), std::string::npos) << r.error().message;
      }
    }
  }
}

}  // namespace
}  // namespace softshell::engine
