#include "softshell/interaction.h"

#include <cmath>

#include <Eigen/SVD>
#include <gtest/gtest.h>

#include "softshell/picking.h"
#include "test_meshes.h"

namespace softshell {
namespace {

TEST(Interaction, LagrangeFormIsTheLimitStencil) {
  const ControlMesh mesh = test::load_asset_mesh("catmark_nonquads.obj");
  const auto ev = LimitEvaluator::create(mesh).value();
  const SurfacePoint p{3, 0, 0.3, 0.7};
  const LimitConstraint c{p, Vec3(0.1, -0.2, 0.3), Vec3(1, 0, 0), std::nullopt};
  const auto rows = to_lagrange(ev, c).value();
  ASSERT_EQ(rows.size(), 2u);
  // Applied to any displacement field, the rows give the limit displacement and its u derivative.
  std::vector<Vec3> u(static_cast<size_t>(mesh.num_vertices()));
  for (size_t i = 0; i < u.size(); ++i) u[i] = Vec3(std::sin(double(i)), std::cos(2.0 * double(i)), 0.1 * double(i));
  std::vector<Vec3> moved = mesh.positions();
  for (size_t i = 0; i < u.size(); ++i) moved[i] += u[i];
  const LimitSample a = ev.evaluate(p), b = ev.evaluate(p, moved);
  auto apply = [&](const LagrangeConstraint& l) {
    Vec3 s = Vec3::Zero();
    for (size_t k = 0; k < l.indices.size(); ++k) s += l.coefficients[k].cwiseProduct(u[static_cast<size_t>(l.indices[k])]);
    return s;
  };
  EXPECT_LT((apply(rows[0]) - (b.position - a.position)).norm(), 1e-12);
  EXPECT_LT((apply(rows[1]) - (b.du - a.du)).norm(), 1e-11);
  EXPECT_EQ(rows[0].values, c.displacement);
  EXPECT_EQ(rows[1].values, Vec3(1, 0, 0));
  // One axis only: the other equations have zero coefficients and values (the server drops them).
  const auto y_only = to_lagrange(ev, c, kAxisY).value();
  ASSERT_EQ(y_only.size(), 2u);
  for (const Vec3& coefficient : y_only[0].coefficients) {
    EXPECT_EQ(coefficient.x(), 0.0);
    EXPECT_EQ(coefficient.z(), 0.0);
  }
  EXPECT_EQ(y_only[0].values, Vec3(0, -0.2, 0));
  EXPECT_FALSE(to_lagrange(ev, c, 0).ok());
  EXPECT_FALSE(to_lagrange(ev, {{99, 0, 0.5, 0.5}, Vec3::Zero(), {}, {}}).ok());
  EXPECT_FALSE(to_lagrange(ev, {p, Vec3(NAN, 0, 0), {}, {}}).ok());
}

TEST(Interaction, SpreadForceKeepsTotalAndMoment) {
  const ControlMesh mesh = test::load_asset_mesh("catmark_torus.obj");
  const auto ev = LimitEvaluator::create(mesh).value();
  const SurfaceForce f{{5, 0, 0.2, 0.9}, Vec3(0, 0, -3)};
  const auto forces = spread_force(ev, f).value();
  EXPECT_EQ(forces.size(), ev.stencil(f.point).size());
  Vec3 total = Vec3::Zero();
  Vec3 first_moment = Vec3::Zero();  // sum of N_A x_A = the limit point (weights reproduce positions)
  double weight_sum = 0.0;
  for (const auto& pf : forces) {
    total += pf.force;
    const double w = pf.force.z() / f.force.z();
    weight_sum += w;
    first_moment += w * mesh.positions()[static_cast<size_t>(pf.index)];
  }
  EXPECT_LT((total - f.force).norm(), 1e-14);
  EXPECT_NEAR(weight_sum, 1.0, 1e-14);
  EXPECT_LT((first_moment - ev.evaluate(f.point).position).norm(), 1e-12);
  EXPECT_FALSE(spread_force(ev, {{5, 0, 2.0, 0.5}, Vec3::UnitX()}).ok());
  EXPECT_FALSE(spread_force(ev, {{5, 0, 0.5, 0.5}, Vec3(INFINITY, 0, 0)}).ok());
}

TEST(Interaction, PushAlongTheRay) {
  Pick pick;
  pick.point = {1, 0, 0.5, 0.5};
  const SurfaceForce f = push(pick, Vec3(0, 0, -2), 5.0);
  EXPECT_EQ(f.point, pick.point);
  EXPECT_LT((f.force - Vec3(0, 0, -5)).norm(), 1e-15);
  EXPECT_EQ(push(pick, Vec3::Zero(), 5.0).force, Vec3::Zero());
  EXPECT_EQ(push(pick, Vec3::UnitX(), NAN).force, Vec3::Zero());
}

TEST(Interaction, GrabFollowsTheHand) {
  const ControlMesh mesh = test::load_asset_mesh("catmark_nonquads.obj");
  const auto ev = LimitEvaluator::create(mesh).value();
  const SurfacePoint p{2, 1, 0.4, 0.6};
  // The shape shown is already deformed (translated): the grab holds the point where it is shown.
  std::vector<Vec3> shown = mesh.positions();
  for (Vec3& x : shown) x += Vec3(0, 0.5, 0);
  const Pose hand0{Vec3(1, 2, 3), Eigen::Quaterniond(Eigen::AngleAxisd(0.3, Vec3::UnitZ()))};
  const Grab g = Grab::begin(ev, p, shown, hand0).value();
  const Vec3 rest = ev.evaluate(p).position;
  EXPECT_LT((g.grabbed_position() - (rest + Vec3(0, 0.5, 0))).norm(), 1e-12);
  EXPECT_LT((g.constraint(hand0).displacement - Vec3(0, 0.5, 0)).norm(), 1e-12);

  // Translation moves the point with the hand.
  Pose moved = hand0;
  moved.position += Vec3(0.1, -0.2, 0.05);
  EXPECT_LT((g.target(moved) - (g.grabbed_position() + Vec3(0.1, -0.2, 0.05))).norm(), 1e-12);
  // Rotating the hand about its own position swings the point around it at the same distance.
  Pose turned = hand0;
  turned.orientation = Eigen::AngleAxisd(0.5, Vec3::UnitY()) * hand0.orientation;
  const Vec3 t = g.target(turned);
  EXPECT_NEAR((t - hand0.position).norm(), (g.grabbed_position() - hand0.position).norm(), 1e-12);
  EXPECT_LT((t - (hand0.position + Eigen::AngleAxisd(0.5, Vec3::UnitY()) * (g.grabbed_position() - hand0.position))).norm(),
            1e-12);
  // Without follow_rotation, only translation counts.
  GrabOptions translate_only;
  translate_only.follow_rotation = false;
  const Grab g2 = Grab::begin(ev, p, shown, hand0, translate_only).value();
  EXPECT_LT((g2.target(turned) - g2.grabbed_position()).norm(), 1e-12);

  // Tangent plane: the tangents turn with the hand.
  GrabOptions tangents;
  tangents.constrain_tangents = true;
  const Grab g3 = Grab::begin(ev, p, mesh.positions(), hand0, tangents).value();
  const LimitSample s = ev.evaluate(p);
  const LimitConstraint c0 = g3.constraint(hand0);
  ASSERT_TRUE(c0.du_displacement && c0.dv_displacement);
  EXPECT_LT(c0.du_displacement->norm(), 1e-12);
  const LimitConstraint c1 = g3.constraint(turned);
  const Eigen::Matrix3d R = Eigen::AngleAxisd(0.5, Vec3::UnitY()).toRotationMatrix();
  EXPECT_LT((*c1.du_displacement - (R * s.du - s.du)).norm(), 1e-12);
  EXPECT_LT((*c1.dv_displacement - (R * s.dv - s.dv)).norm(), 1e-12);
  EXPECT_FALSE(g.constraint(hand0).du_displacement.has_value());

  // Bad input.
  EXPECT_FALSE(Grab::begin(ev, {99, 0, 0.5, 0.5}, shown, hand0).ok());
  EXPECT_FALSE(Grab::begin(ev, p, {Vec3::Zero()}, hand0).ok());
  EXPECT_FALSE(Grab::begin(ev, p, shown, Pose{Vec3(NAN, 0, 0), {}}).ok());
  EXPECT_FALSE(Grab::begin(ev, p, shown, Pose{Vec3::Zero(), Eigen::Quaterniond(0, 0, 0, 0)}).ok());
  // A NaN hand later never produces NaN constraints.
  const LimitConstraint safe = g.constraint(Pose{Vec3(NAN, 0, 0), {}});
  EXPECT_TRUE(safe.displacement.allFinite());
}

TEST(Interaction, GrabFromAPick) {
  const ControlMesh mesh = test::load_asset_mesh("catmark_torus.obj");
  const auto ev = LimitEvaluator::create(mesh).value();
  auto t = Tessellation::create(ev, 3).value();
  auto picker = Picker::create(t).value();
  const Vec3 target = t.vertices()[17], normal = t.normals()[17];
  const Ray ray{target + 2.0 * normal + Vec3(0.01, 0.02, 0.0), -normal};
  auto pick = picker.pick(ray).value();
  ASSERT_TRUE(pick.has_value());
  const Pose hand{ray.origin, Eigen::Quaterniond::Identity()};
  const Grab g = Grab::begin(ev, pick->point, t.control_positions(), hand).value();
  EXPECT_LT((g.grabbed_position() - pick->position).norm(), 1e-12);
}

// A flat plate lying on the floor: one limit point per face; the rows are independent and fix all
// rigid motions.
TEST(Interaction, FloorHoldsAPlateLyingOnIt) {
  const ControlMesh plate = test::make_grid(4, 3, 2.0, 1.5);
  const auto ev = LimitEvaluator::create(plate).value();
  auto t = Tessellation::create(ev, 2).value();
  const Plane floor{Vec3::Zero(), Vec3(0, 0, 2)};
  const FloorContact all = floor_contact(t, floor).value();
  EXPECT_EQ(all.points.size(), 12u);
  EXPECT_EQ(all.limit_constraints.size(), 12u);
  EXPECT_TRUE(all.lagrange_constraints.empty());
  EXPECT_EQ(all.touching_samples, static_cast<int32_t>(t.vertices().size()));
  EXPECT_TRUE(all.fixes_rigid_motion);
  for (const auto& c : all.limit_constraints) EXPECT_LT(c.displacement.norm(), 1e-15);
  // The constrained limit stencils are linearly independent (well-posed Lagrange rows).
  Eigen::MatrixXd A = Eigen::MatrixXd::Zero(static_cast<Eigen::Index>(all.points.size()), plate.num_vertices());
  for (size_t r = 0; r < all.points.size(); ++r) {
    const LimitStencil st = ev.stencil(all.points[r]);
    for (size_t k = 0; k < st.size(); ++k) A(static_cast<Eigen::Index>(r), st.indices[k]) += st.position[k];
  }
  Eigen::JacobiSVD<Eigen::MatrixXd> svd(A);
  EXPECT_GT(svd.singularValues().minCoeff(), 1e-3 * svd.singularValues().maxCoeff());

  // Normal only: in-plane motions stay free, and the constraints are single-axis Lagrange rows.
  FloorOptions normal_only;
  normal_only.axes = FloorAxes::kNormal;
  const FloorContact z = floor_contact(t, floor, normal_only).value();
  EXPECT_EQ(z.lagrange_constraints.size(), 12u);
  EXPECT_TRUE(z.limit_constraints.empty());
  EXPECT_FALSE(z.fixes_rigid_motion);
  for (const auto& l : z.lagrange_constraints) {
    for (const Vec3& c : l.coefficients) {
      EXPECT_EQ(c.x(), 0.0);
      EXPECT_EQ(c.y(), 0.0);
    }
  }
  DeformationRequest req;
  all.add_to(req);
  z.add_to(req);
  EXPECT_EQ(req.limit_constraints.size(), 12u);
  EXPECT_EQ(req.lagrange_constraints.size(), 12u);
}

TEST(Interaction, FloorUnderARoundedCube) {
  const ControlMesh cube = test::load_asset_mesh("catmark_cube.obj");
  const auto ev = LimitEvaluator::create(cube).value();
  auto t = Tessellation::create(ev, 4).value();
  double lowest = std::numeric_limits<double>::infinity();
  for (const Vec3& x : t.vertices()) lowest = std::min(lowest, x.y());
  const Plane floor{Vec3(0, lowest, 0), Vec3::UnitY()};
  // A tight tolerance touches only around the bottom centre: one face, one point, rotations free.
  FloorOptions tight;
  tight.tolerance = 1e-6;
  const FloorContact one = floor_contact(t, floor, tight).value();
  EXPECT_EQ(one.points.size(), 1u);
  EXPECT_FALSE(one.fixes_rigid_motion);
  // A looser one reaches the bottom face's neighbours: several points around, determined.
  FloorOptions loose;
  loose.tolerance = 0.05 * cube.bounding_diagonal();
  const FloorContact many = floor_contact(t, floor, loose).value();
  EXPECT_GE(many.points.size(), 3u);
  EXPECT_TRUE(many.fixes_rigid_motion);
  for (const SurfacePoint& p : many.points) {
    EXPECT_LE(ev.evaluate(p).position.y() - lowest, loose.tolerance + 1e-12);
  }
  // Nothing touches a floor far below.
  const FloorContact none = floor_contact(t, {Vec3(0, lowest - 1.0, 0), Vec3::UnitY()}).value();
  EXPECT_TRUE(none.points.empty());
  EXPECT_FALSE(none.fixes_rigid_motion);
}

TEST(Interaction, FloorHoldsOrSnapsADeformedShape) {
  const ControlMesh plate = test::make_grid(3, 3);
  const auto ev = LimitEvaluator::create(plate).value();
  auto t = Tessellation::create(ev, 2).value();
  std::vector<Vec3> lifted = plate.positions();
  for (Vec3& x : lifted) x.z() += 0.002;
  t.update(lifted);
  FloorOptions options;
  options.tolerance = 0.01;
  const FloorContact held = floor_contact(t, {Vec3::Zero(), Vec3::UnitZ()}, options).value();
  ASSERT_FALSE(held.limit_constraints.empty());
  for (const auto& c : held.limit_constraints) EXPECT_LT((c.displacement - Vec3(0, 0, 0.002)).norm(), 1e-12);
  options.snap = true;
  const FloorContact snapped = floor_contact(t, {Vec3::Zero(), Vec3::UnitZ()}, options).value();
  for (const auto& c : snapped.limit_constraints) EXPECT_LT(c.displacement.norm(), 1e-12);
  options.axes = FloorAxes::kNormal;
  const FloorContact snapped_z = floor_contact(t, {Vec3::Zero(), Vec3::UnitZ()}, options).value();
  for (const auto& l : snapped_z.lagrange_constraints) EXPECT_LT(l.values.norm(), 1e-12);
}

TEST(Interaction, FloorRejectsBadInput) {
  const auto ev = LimitEvaluator::create(test::make_grid(2, 2)).value();
  auto t = Tessellation::create(ev, 1).value();
  EXPECT_EQ(floor_contact(t, {Vec3(NAN, 0, 0), Vec3::UnitZ()}).error().code, ErrorCode::kInvalidArgument);
  EXPECT_EQ(floor_contact(t, {Vec3::Zero(), Vec3::Zero()}).error().code, ErrorCode::kInvalidArgument);
  FloorOptions tilted;
  tilted.axes = FloorAxes::kNormal;
  const auto r = floor_contact(t, {Vec3::Zero(), Vec3(0, 0.1, 1)}, tilted);
  EXPECT_EQ(r.error().code, ErrorCode::kInvalidArgument);
  EXPECT_NE(r.error().message.find("axis"), std::string::npos);
  FloorOptions nan_tolerance;
  nan_tolerance.tolerance = NAN;
  EXPECT_FALSE(floor_contact(t, {Vec3::Zero(), Vec3::UnitZ()}, nan_tolerance).ok());
  // A downward axis normal is fine for kNormal.
  EXPECT_TRUE(floor_contact(t, {Vec3(0, 0, 1), Vec3(0, 0, -3)}, tilted).ok());
}

}  // namespace
}  // namespace softshell
