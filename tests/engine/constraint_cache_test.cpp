// Constraint rows that repeat from request to request (a floor, a held grab, groups the caller
// names) are cached with the factor: the cached path gives the uncached answer, and the cache
// entries count against the budget.
#include <thread>

#include <gtest/gtest.h>

#include "softshell/engine/solver.h"
#include "softshell/interaction.h"
#include "softshell/tessellation.h"
#include "test_meshes.h"

namespace softshell::engine {
namespace {

double relative_difference(const Eigen::VectorXd& a, const Eigen::VectorXd& b) {
  return (a - b).norm() / std::max(a.norm(), 1e-300);
}

// spot's control mesh on a floor of limit constraints (as the SDK builds it), and grabs.
struct Floor {
  ControlMesh mesh = test::load_asset_mesh("spot_control_mesh.obj");
  std::shared_ptr<const ShellModel> model = ShellModel::build(mesh, Material{2e9, 0.35, 0.002, 1000.0}).value();
  FloorContact floor;
  Floor() {
    const Tessellation surface = Tessellation::create(model->evaluator(), 3).value();
    double floor_y = std::numeric_limits<double>::infinity();
    for (const Vec3& p : surface.vertices()) floor_y = std::min(floor_y, p.y());
    for (double tolerance : {0.01, 0.03, 0.06, 0.12}) {
      floor = floor_contact(surface, Plane{Vec3(0.0, floor_y, 0.0), Vec3::UnitY()}, {tolerance * mesh.bounding_diagonal()}).value();
      if (floor.fixes_rigid_motion) break;
    }
  }
  // The floor, then a grab at a point of face `f` pulled by `pull` (and a small load).
  DeformationRequest request(int32_t f, const Vec3& pull) const {
    DeformationRequest r;
    floor.add_to(r);
    r.limit_constraints.push_back({{f, 0, 0.4, 0.6}, pull, {}, {}});
    r.surface_load = Vec3(0.0, -2.0, 0.0);
    return r;
  }
  int floor_rows() const { return static_cast<int>(3 * floor.limit_constraints.size()); }
};

const Floor& floor_setup() {  // built once for all tests (immutable)
  static const Floor f;
  return f;
}

TEST(ConstraintCache, RepeatedRowsAreCachedAndGiveTheUncachedAnswer) {
  const Floor& f = floor_setup();
  ASSERT_TRUE(f.floor.fixes_rigid_motion);
  ASSERT_GE(f.floor_rows(), 12);
  auto cache = std::make_shared<FactorCache>();
  Solver solver(f.model, cache);
  const Vec3 pull(0.01, 0.02, -0.01);
  // Each request has a new grab; the floor repeats. First solve: nothing known; second: the
  // floor was in the previous solve, so it is kept; from then on it is reused.
  for (int k = 0; k < 6; ++k) {
    const DeformationRequest request = f.request(10 + 7 * k, pull);
    auto cached = solver.solve(request);
    ASSERT_TRUE(cached.ok()) << cached.error().message;
    EXPECT_EQ(cached->stats.path, SolvePath::kCachedFactor);
    EXPECT_EQ(cached->stats.reused_rows, k >= 2 ? f.floor_rows() : 0) << k;
    EXPECT_EQ(cached->stats.cached_rows, k == 1 ? f.floor_rows() : 0) << k;
    // The same request on a fresh cache (nothing reused) and on the robust path.
    Solver fresh(f.model, std::make_shared<FactorCache>());
    auto uncached = fresh.solve(request);
    ASSERT_TRUE(uncached.ok());
    EXPECT_EQ(uncached->stats.reused_rows, 0);
    EXPECT_LT(relative_difference(cached->displacement, uncached->displacement), 1e-11) << k;
    auto robust = solver.solve_with_fallback(request);
    ASSERT_TRUE(robust.ok());
    EXPECT_LT(relative_difference(cached->displacement, robust->displacement), 1e-9) << k;
  }
  EXPECT_EQ(cache->stats().constraint_blocks, 1u);
  EXPECT_GE(cache->stats().constraint_hits, 4u);

  // A held grab that moves: the same coefficients with new targets, kept after its second solve
  // on top of the floor (a block of floor + grab), then reused with every new target.
  for (int k = 0; k < 4; ++k) {
    const DeformationRequest request = f.request(3, pull * (1.0 + 0.5 * k));
    auto moving = solver.solve(request);
    ASSERT_TRUE(moving.ok()) << moving.error().message;
    if (k >= 2) {
      EXPECT_EQ(moving->stats.reused_rows, f.floor_rows() + 3) << k;
    }
    Solver fresh(f.model, std::make_shared<FactorCache>());
    EXPECT_LT(relative_difference(moving->displacement, fresh.solve(request)->displacement), 1e-11) << k;
  }
  // And a new grab after it: the floor's block (a prefix) still serves.
  auto next = solver.solve(f.request(40, pull));
  ASSERT_TRUE(next.ok());
  EXPECT_EQ(next->stats.reused_rows, f.floor_rows());
}

TEST(ConstraintCache, GroupsNamedByTheCallerAreCachedAtTheirFirstUse) {
  const Floor& f = floor_setup();
  auto cache = std::make_shared<FactorCache>();
  Solver solver(f.model, cache);
  SolveOptions options;
  options.repeated.push_back({0, f.floor.limit_constraints.size(), 0, 0});  // the floor comes first
  for (int k = 0; k < 3; ++k) {
    const DeformationRequest request = f.request(20 + 5 * k, Vec3(0.0, 0.03, 0.0));
    auto solution = solver.solve(request, options);
    ASSERT_TRUE(solution.ok()) << solution.error().message;
    EXPECT_EQ(solution->stats.cached_rows, k == 0 ? f.floor_rows() : 0);
    EXPECT_EQ(solution->stats.reused_rows, k == 0 ? 0 : f.floor_rows());
    Solver fresh(f.model, std::make_shared<FactorCache>());
    EXPECT_LT(relative_difference(solution->displacement, fresh.solve(request)->displacement), 1e-11);
  }
}

// Many solves at once on one cache, each thread its own grab on the same floor: the blocks are
// shared and every answer is the serial one.
TEST(ConstraintCache, ConcurrentSolvesShareTheBlocks) {
  const Floor& f = floor_setup();
  auto cache = std::make_shared<FactorCache>();
  Solver solver(f.model, cache);
  ASSERT_TRUE(solver.solve(f.request(1, Vec3(0.0, 0.01, 0.0))).ok());
  std::vector<Eigen::VectorXd> answers(8);
  std::vector<std::thread> threads;
  for (int t = 0; t < 8; ++t) {
    threads.emplace_back([&, t] {
      for (int k = 0; k < 3; ++k) {
        auto r = solver.solve(f.request(10 + 9 * t, Vec3(0.0, 0.01 * (k + 1), 0.0)));
        if (r.ok()) answers[static_cast<size_t>(t)] = r->displacement;
      }
    });
  }
  for (auto& t : threads) t.join();
  // The floor's block, and perhaps some floor + grab blocks (when one thread's solves followed
  // each other, its grab was "the same as last time").
  EXPECT_GE(cache->stats().constraint_blocks, 1u);
  EXPECT_LE(cache->stats().constraint_blocks, 9u);
  EXPECT_GE(cache->stats().constraint_hits, 8u);
  for (int t = 0; t < 8; ++t) {
    Solver fresh(f.model, std::make_shared<FactorCache>());
    auto serial = fresh.solve(f.request(10 + 9 * t, Vec3(0.0, 0.03, 0.0)));
    ASSERT_TRUE(serial.ok());
    ASSERT_EQ(answers[static_cast<size_t>(t)].size(), serial->displacement.size()) << t;
    EXPECT_LT(relative_difference(answers[static_cast<size_t>(t)], serial->displacement), 1e-11) << t;
  }
}

TEST(ConstraintCache, BlocksCountAgainstTheBudget) {
  const Floor& f = floor_setup();
  const DeformationRequest first = f.request(10, Vec3(0.0, 0.02, 0.0)), second = f.request(30, Vec3(0.0, 0.02, 0.0));
  // Plenty of room: factor and floor block are kept, and the bytes add up.
  auto roomy = std::make_shared<FactorCache>();
  Solver solver(f.model, roomy);
  ASSERT_TRUE(solver.solve(first).ok());
  const size_t factor_only = roomy->stats().bytes;
  ASSERT_TRUE(solver.solve(second).ok());
  const FactorCacheStats with_block = roomy->stats();
  EXPECT_EQ(with_block.constraint_blocks, 1u);
  EXPECT_GT(with_block.constraint_bytes, 0u);
  EXPECT_GE(with_block.bytes, factor_only + with_block.constraint_bytes);
  EXPECT_LE(with_block.bytes, with_block.budget);

  // Room for the factor but not for the block: the block is not kept, the factor stays, and
  // the answers are the same.
  auto tight = std::make_shared<FactorCache>(factor_only + with_block.constraint_bytes / 2);
  Solver small(f.model, tight);
  for (const DeformationRequest* request : {&first, &second, &first}) {
    auto solution = small.solve(*request);
    ASSERT_TRUE(solution.ok()) << solution.error().message;
    EXPECT_EQ(solution->stats.reused_rows, 0);
    Solver fresh(f.model, std::make_shared<FactorCache>());
    EXPECT_LT(relative_difference(solution->displacement, fresh.solve(*request)->displacement), 1e-11);
    EXPECT_LE(tight->stats().bytes, tight->stats().budget);
  }
  EXPECT_EQ(tight->stats().entries, 1u);
  EXPECT_EQ(tight->stats().constraint_blocks, 0u);
  EXPECT_GE(tight->stats().evictions, 1u);
  // Forgetting the model drops its blocks too.
  roomy->forget_model(f.model->id());
  EXPECT_EQ(roomy->stats().bytes, 0u);
  EXPECT_EQ(roomy->stats().constraint_blocks, 0u);
}

}  // namespace
}  // namespace softshell::engine
