#include "softshell/bullet/force_accumulator.h"

#include <random>

#include <gtest/gtest.h>

#include "test_meshes.h"

namespace softshell::bullet {
namespace {

TEST(ForceAccumulator, SpreadsWithTheLimitWeightsAndKeepsTheTotal) {
  const ControlMesh mesh = test::load_asset_mesh("catmark_nonquads.obj");
  auto evaluator = LimitEvaluator::create(mesh).value();
  ForceAccumulator acc(evaluator);
  std::mt19937 rng(1);
  std::uniform_real_distribution<double> unit(0.0, 1.0), signed_unit(-1.0, 1.0);
  Vec3 total = Vec3::Zero();
  std::vector<Vec3> expected(size_t(mesh.num_vertices()), Vec3::Zero());
  for (int k = 0; k < 50; ++k) {
    const int32_t face = int32_t(rng() % uint32_t(mesh.num_faces()));
    const SurfacePoint p{face, int32_t(rng() % uint32_t(evaluator.num_subfaces(face))), unit(rng), unit(rng)};
    const Vec3 f(signed_unit(rng), signed_unit(rng), signed_unit(rng));
    acc.add(p, f);
    total += f;
    const LimitStencil st = evaluator.stencil(p);
    for (size_t i = 0; i < st.size(); ++i) expected[size_t(st.indices[i])] += st.position[i] * f;
  }
  EXPECT_LT((acc.total() - total).norm(), 1e-12);
  for (size_t i = 0; i < expected.size(); ++i) EXPECT_LT((acc.forces()[i] - expected[i]).norm(), 1e-12);

  std::vector<PointForce> forces;
  acc.append_to(forces);
  Vec3 sum = Vec3::Zero();
  for (size_t i = 0; i < forces.size(); ++i) {
    if (i > 0) {
      EXPECT_LT(forces[i - 1].index, forces[i].index);
    }
    sum += forces[i].force;
  }
  EXPECT_LT((sum - total).norm(), 1e-12);

  // The virtual work of the spread forces equals the work of the point forces for any motion.
  acc.clear();
  EXPECT_TRUE(acc.empty());
  EXPECT_TRUE(acc.total().isZero(0.0));
  for (const Vec3& f : acc.forces()) EXPECT_TRUE(f.isZero(0.0));
  EXPECT_THROW(acc.add(SurfacePoint{mesh.num_faces(), 0, 0.5, 0.5}, Vec3::UnitX()), Exception);
  EXPECT_THROW(acc.add(-1, Vec3::UnitX()), Exception);
}

TEST(ForceAccumulator, VirtualWorkMatchesThePointForce) {
  const ControlMesh mesh = test::load_asset_mesh("catmark_helmet.obj");
  auto evaluator = LimitEvaluator::create(mesh).value();
  ForceAccumulator acc(evaluator);
  const SurfacePoint p{3, 0, 0.3, 0.8};
  const Vec3 f(0.2, -1.0, 0.4);
  acc.add(p, f);
  // A random motion of the control points moves the limit point by S u.
  std::mt19937 rng(5);
  std::normal_distribution<double> normal;
  std::vector<Vec3> u(size_t(mesh.num_vertices())), moved = mesh.positions();
  for (size_t i = 0; i < u.size(); ++i) {
    u[i] = Vec3(normal(rng), normal(rng), normal(rng));
    moved[i] += u[i];
  }
  double work = 0.0;
  for (size_t i = 0; i < u.size(); ++i) work += acc.forces()[i].dot(u[i]);
  const Vec3 dp = evaluator.evaluate(p, moved).position - evaluator.evaluate(p).position;
  EXPECT_NEAR(work, f.dot(dp), 1e-9);
}

TEST(ForceAccumulator, RelativeDifferenceBlendAndAssign) {
  auto evaluator = LimitEvaluator::create(test::make_grid(4, 4)).value();
  ForceAccumulator a(evaluator), b(evaluator);
  EXPECT_EQ(a.relative_difference(b), 0.0);
  a.add(3, Vec3(0, 0, 2));
  EXPECT_EQ(a.relative_difference(b), 1.0);
  EXPECT_EQ(b.relative_difference(a), 1.0);
  b.add(3, Vec3(0, 0, 2));
  EXPECT_EQ(a.relative_difference(b), 0.0);
  b.add(7, Vec3(0, 0, 0.02));
  EXPECT_NEAR(a.relative_difference(b), 0.02 / std::sqrt(4.0 + 0.0004), 1e-12);
  EXPECT_NEAR(b.relative_difference(a), 0.02 / std::sqrt(4.0 + 0.0004), 1e-12);

  // Exponential smoothing toward a target converges to it and keeps the total consistent.
  ForceAccumulator s(evaluator);
  for (int k = 0; k < 200; ++k) s.blend_toward(b, 0.1);
  EXPECT_LT(s.relative_difference(b), 1e-8);
  EXPECT_LT((s.total() - b.total()).norm(), 1e-8);
  // Toward nothing, small forces are dropped.
  ForceAccumulator none(evaluator);
  for (int k = 0; k < 100 && !s.empty(); ++k) s.blend_toward(none, 0.5, 1e-3);
  EXPECT_TRUE(s.empty());
  EXPECT_TRUE(s.total().isZero(0.0));
  // alpha = 1 copies.
  s.blend_toward(a, 1.0);
  EXPECT_EQ(s.relative_difference(a), 0.0);
  s.assign(b);
  EXPECT_EQ(s.relative_difference(b), 0.0);
  EXPECT_EQ(s.touched().size(), 2u);

  ForceAccumulator other(LimitEvaluator::create(test::make_grid(2, 2)).value());
  EXPECT_THROW(s.blend_toward(other, 0.5), Exception);
  EXPECT_THROW(s.assign(other), Exception);
}

}  // namespace
}  // namespace softshell::bullet
