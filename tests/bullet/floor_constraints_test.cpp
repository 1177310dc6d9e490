#include "softshell/bullet/floor_constraints.h"

#include <cmath>
#include <numbers>
#include <set>

#include <gtest/gtest.h>

#include "softshell/interaction.h"
#include "test_meshes.h"

namespace softshell::bullet {
namespace {

// An arch over x in [0, 1]: z = 0.3 sin(pi x), its two straight edges on z = 0.
ControlMesh arch(int nx = 8, int ny = 4) {
  return test::make_grid(nx, ny, 1.0, 0.5, [](double x, double) { return 0.3 * std::sin(std::numbers::pi * x); });
}

Tessellation tessellate(const ControlMesh& mesh, int level = 2) {
  return Tessellation::create(LimitEvaluator::create(mesh).value(), level).value();
}

TEST(FloorConstraints, HoldTheControlPointsWhereTheArchTouches) {
  const ControlMesh mesh = arch();
  const Tessellation t = tessellate(mesh);
  FloorSettings floor;
  floor.enabled = true;
  floor.normal = Vec3::UnitZ();
  auto held = floor_constraints(t, Eigen::Isometry3d::Identity(), floor);
  ASSERT_TRUE(held.ok()) << held.error().message;
  std::set<int32_t> expected;
  for (int j = 0; j <= 4; ++j) {
    expected.insert(test::grid_index(8, 0, j));
    expected.insert(test::grid_index(8, 8, j));
  }
  std::set<int32_t> got;
  for (const VertexConstraint& c : *held) {
    got.insert(c.index);
    EXPECT_EQ(c.mask, kAxisAll);
    EXPECT_TRUE(c.displacement.isZero(0.0));
  }
  EXPECT_EQ(got, expected);
  for (size_t i = 1; i < held->size(); ++i) EXPECT_LT((*held)[i - 1].index, (*held)[i].index);
}

TEST(FloorConstraints, FollowThePlacementInTheWorld) {
  const ControlMesh mesh = arch();
  const Tessellation t = tessellate(mesh);
  FloorSettings floor;
  floor.normal = Vec3::UnitY();  // y-up world
  floor.point = Vec3(0.0, -2.0, 0.0);
  floor.mask = kAxisY;
  // The arch's local z is the world's y, and it stands on y = -2.
  Eigen::Isometry3d placement = Eigen::Isometry3d::Identity();
  placement.linear() = Eigen::AngleAxisd(-std::numbers::pi / 2, Vec3::UnitX()).toRotationMatrix();
  placement.translation() = Vec3(5.0, -2.0, 1.0);
  auto held = floor_constraints(t, placement, floor);
  ASSERT_TRUE(held.ok());
  EXPECT_EQ(held->size(), 10u);
  for (const VertexConstraint& c : *held) EXPECT_EQ(c.mask, kAxisY);

  // Lifted off the floor: nothing touches.
  placement.translation().y() += 0.1;
  EXPECT_TRUE(floor_constraints(t, placement, floor)->empty());
  // A large tolerance reaches up the arch (0.15 above the floor: x < 1/6, the second rows).
  floor.tolerance = 0.25;
  EXPECT_GT(floor_constraints(t, placement, floor)->size(), 10u);
}

// One rule decides what touches for both holds (the SDK's floor_touching_samples): the default
// tolerance is 1e-3 of the rest mesh's size, also once the shape shown has been deformed (here
// stretched to twice its size, which would double a tolerance taken from the shown shape).
TEST(FloorConstraints, BothHoldsUseTheSdksTouchingRule) {
  const ControlMesh mesh = arch();
  Tessellation t = tessellate(mesh);
  const double rest_size = mesh.bounding_diagonal();
  std::vector<Vec3> stretched = mesh.positions();
  for (Vec3& p : stretched) p.head<2>() *= 2.0;
  // Just above the default tolerance of the rest size, just below twice it.
  for (Vec3& p : stretched) {
    if (std::abs(p.z()) < 1e-12) p.z() = 1.5e-3 * rest_size;
  }
  t.update(stretched);
  FloorSettings floor;
  floor.normal = Vec3::UnitZ();
  const auto touching = floor_touching_samples(t, Plane{Vec3::Zero(), Vec3::UnitZ()}, -1.0);
  ASSERT_TRUE(touching.ok()) << touching.error().message;
  EXPECT_TRUE(touching->empty());
  EXPECT_TRUE(floor_constraints(t, Eigen::Isometry3d::Identity(), floor)->empty());
  floor.hold = FloorHold::kLimitPoints;
  EXPECT_TRUE(floor_request(t, Eigen::Isometry3d::Identity(), floor)->limit_constraints.empty());

  // With a tolerance that reaches them, both holds hold exactly the touching samples' parts.
  floor.tolerance = 2e-3 * rest_size;
  const auto reached = floor_touching_samples(t, Plane{Vec3::Zero(), Vec3::UnitZ()}, floor.tolerance).value();
  EXPECT_FALSE(reached.empty());
  std::set<int32_t> faces;
  for (int32_t i : reached) faces.insert(t.vertex_points()[static_cast<size_t>(i)].face);
  const DeformationRequest limit_points = floor_request(t, Eigen::Isometry3d::Identity(), floor).value();
  EXPECT_EQ(limit_points.limit_constraints.size(), faces.size());
  floor.hold = FloorHold::kControlPoints;
  EXPECT_EQ(floor_constraints(t, Eigen::Isometry3d::Identity(), floor)->size(), 10u);

  EXPECT_EQ(coordinate_axis(Vec3(0, -3, 0)), 1);
  EXPECT_EQ(coordinate_axis(Vec3(0, 1, 1e-3)), -1);  // tilted by 1 mrad
  EXPECT_EQ(coordinate_axis(Vec3::Zero()), -1);
  EXPECT_FALSE(floor_touching_samples(t, Plane{Vec3::Zero(), Vec3::Zero()}, -1.0).ok());
  EXPECT_FALSE(floor_touching_samples(t, Plane{Vec3::Zero(), Vec3::UnitZ()}, std::nan("")).ok());
}

TEST(FloorConstraints, RequestHoldsControlPointsOrLimitPoints) {
  const ControlMesh mesh = arch();
  const Tessellation t = tessellate(mesh);
  // A y-up world: the arch's local z is the world's y, standing on y = -2.
  Eigen::Isometry3d placement = Eigen::Isometry3d::Identity();
  placement.linear() = Eigen::AngleAxisd(-std::numbers::pi / 2, Vec3::UnitX()).toRotationMatrix();
  placement.translation() = Vec3(5.0, -2.0, 1.0);
  FloorSettings floor;
  floor.normal = Vec3::UnitY();
  floor.point = Vec3(0.0, -2.0, 0.0);

  auto vertex = floor_request(t, placement, floor);
  ASSERT_TRUE(vertex.ok()) << vertex.error().message;
  const auto direct = floor_constraints(t, placement, floor).value();
  ASSERT_EQ(vertex->vertex_constraints.size(), direct.size());
  for (size_t i = 0; i < direct.size(); ++i) EXPECT_EQ(vertex->vertex_constraints[i].index, direct[i].index);
  EXPECT_TRUE(vertex->limit_constraints.empty());
  EXPECT_TRUE(vertex->fits_binary_layout());

  floor.hold = FloorHold::kLimitPoints;
  auto limit = floor_request(t, placement, floor);
  ASSERT_TRUE(limit.ok()) << limit.error().message;
  EXPECT_TRUE(limit->vertex_constraints.empty());
  ASSERT_EQ(limit->limit_constraints.size(), 8u);  // one per face along each foot
  const auto evaluator = LimitEvaluator::create(mesh).value();
  for (const LimitConstraint& c : limit->limit_constraints) {
    EXPECT_NEAR(evaluator.evaluate(c.point).position.z(), 0.0, 1e-3);  // on the floor (local z = 0)
    EXPECT_TRUE(c.displacement.isZero(1e-12));
  }

  // Only the normal: one Lagrange row per point, on the normal's axis in the shell's frame (z).
  floor.mask = kAxisZ;
  auto normal = floor_request(t, placement, floor);
  ASSERT_TRUE(normal.ok()) << normal.error().message;
  EXPECT_EQ(normal->lagrange_constraints.size(), 8u);
  floor.mask = kAxisY;  // the world's axis, not the shell's
  EXPECT_EQ(floor_request(t, placement, floor).error().code, ErrorCode::kInvalidArgument);
}

TEST(FloorConstraints, RejectBadPlanes) {
  const Tessellation t = tessellate(arch(), 1);
  FloorSettings floor;
  floor.normal = Vec3::Zero();
  EXPECT_EQ(floor_constraints(t, Eigen::Isometry3d::Identity(), floor).error().code, ErrorCode::kInvalidArgument);
  floor.normal = Vec3::UnitZ();
  floor.point.x() = std::nan("");
  EXPECT_EQ(floor_constraints(t, Eigen::Isometry3d::Identity(), floor).error().code, ErrorCode::kInvalidArgument);
  floor.point = Vec3::Zero();
  floor.mask = 0;
  EXPECT_EQ(floor_constraints(t, Eigen::Isometry3d::Identity(), floor).error().code, ErrorCode::kInvalidArgument);
  floor.mask = 8;
  EXPECT_EQ(floor_constraints(t, Eigen::Isometry3d::Identity(), floor).error().code, ErrorCode::kInvalidArgument);
  floor.mask = kAxisAll;
  floor.tolerance = std::numeric_limits<double>::infinity();
  EXPECT_EQ(floor_constraints(t, Eigen::Isometry3d::Identity(), floor).error().code, ErrorCode::kInvalidArgument);
}

}  // namespace
}  // namespace softshell::bullet
