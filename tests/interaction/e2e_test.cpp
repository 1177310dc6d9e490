// End-to-end: the interaction helpers and levels of detail through a real in-process server
// (EmbeddedSession: service + engine), as an application uses them.

#include <cmath>
#include <thread>

#include <gtest/gtest.h>

#include "softshell/embedded_session.h"
#include "softshell/interaction.h"
#include "softshell/level_of_detail.h"
#include "softshell/picking.h"
#include "test_meshes.h"

namespace softshell {
namespace {

// An aluminium-like shell, 1 cm thick: the plates below are 1 m wide.
Material shell_material() { return Material{7.0e10, 0.3, 0.01, 2700.0}; }

// A gently curved n x n plate over [0, 1]^2 (a shell, not a flat plate, so membrane and bending
// both matter).
ControlMesh curved_plate(int n) {
  return test::make_grid(n, n, 1.0, 1.0, [](double x, double y) { return 0.1 * x * (1.0 - x) + 0.05 * y * y; });
}

// The edge y = 0 clamped: the first two rows of control points fixed on all axes.
std::vector<VertexConstraint> clamp_first_rows(int n, int rows = 2) {
  std::vector<VertexConstraint> out;
  for (int j = 0; j < rows; ++j) {
    for (int i = 0; i <= n; ++i) out.push_back({test::grid_index(n, i, j), kAxisAll, Vec3::Zero()});
  }
  return out;
}

// The grab of paper Section 6.2: pick with a ray from the hand, move and turn the hand, and the
// deformed limit surface at the picked point is exactly where the hand put it (and so is its
// tangent plane when asked for).
TEST(EndToEnd, GrabMovesTheLimitPointExactly) {
  EmbeddedSession session;
  const int n = 6;
  const ControlMesh mesh = curved_plate(n);
  const double size = mesh.bounding_diagonal();
  const GeomId id = session.upload(mesh, shell_material()).value().id;
  const LimitEvaluator ev = LimitEvaluator::create(mesh).value();
  const Tessellation surface = Tessellation::create(ev, 3).value();
  const Picker picker = Picker::create(surface).value();

  const Ray ray{Vec3(0.63, 0.81, 1.0), Vec3(0.05, -0.1, -1.0)};
  const auto pick = picker.pick(ray).value();
  ASSERT_TRUE(pick.has_value());
  ASSERT_EQ(pick->status, RefineStatus::kConverged);

  for (bool tangents : {false, true}) {
    GrabOptions options;
    options.constrain_tangents = tangents;
    const Pose hand0{ray.origin, Eigen::Quaterniond::Identity()};
    const Grab grab = Grab::begin(ev, pick->point, surface.control_positions(), hand0, options).value();
    Pose hand = hand0;
    hand.position += Vec3(0.0, -0.01, 0.03);
    hand.orientation = Eigen::AngleAxisd(0.02, Vec3::UnitX()) * hand.orientation;

    DeformationRequest request;
    request.vertex_constraints = clamp_first_rows(n);
    const LimitConstraint c = grab.constraint(hand);
    request.limit_constraints.push_back(c);
    const DeformationResult result = session.deform(id, request).value();
    ASSERT_EQ(result.positions.size(), static_cast<size_t>(mesh.num_vertices()));

    const LimitSample deformed = ev.evaluate(pick->point, result.positions);
    const Vec3 target = grab.target(hand);
    EXPECT_LT((deformed.position - target).norm(), 1e-9 * size) << "tangents " << tangents;
    EXPECT_GT((target - pick->position).norm(), 0.01);  // it really moved
    if (tangents) {
      const LimitSample rest = ev.evaluate(pick->point);
      EXPECT_LT((deformed.du - (rest.du + *c.du_displacement)).norm(), 1e-9 * rest.du.norm());
      EXPECT_LT((deformed.dv - (rest.dv + *c.dv_displacement)).norm(), 1e-9 * rest.dv.norm());
    }

    // The same through the Lagrange form (what the binary layout carries), asynchronously.
    DeformationRequest lagrange;
    lagrange.vertex_constraints = request.vertex_constraints;
    lagrange.lagrange_constraints = to_lagrange(ev, c).value();
    auto future = session.deform_async(id, lagrange);
    const DeformationResult async_result = future.get().value();
    EXPECT_GT(async_result.res_id, result.res_id);
    for (size_t i = 0; i < result.positions.size(); ++i) {
      EXPECT_LT((async_result.positions[i] - result.positions[i]).norm(), 1e-9 * size);
    }
  }
}

// A push: a point force at a pick spread with the limit weights, sent as a surface force (the
// server spreads it) or as explicit point forces (the client does): the same deformation.
TEST(EndToEnd, PushAsSurfaceForceOrPointForces) {
  EmbeddedSession session;
  const int n = 6;
  const ControlMesh mesh = curved_plate(n);
  const GeomId id = session.upload(mesh, shell_material()).value().id;
  const LimitEvaluator ev = LimitEvaluator::create(mesh).value();
  const Tessellation surface = Tessellation::create(ev, 2).value();
  const Picker picker = Picker::create(surface).value();
  const Ray ray{Vec3(0.4, 0.7, 1.0), Vec3(0, 0, -1)};
  const auto pick = picker.pick(ray).value();
  ASSERT_TRUE(pick.has_value());
  const SurfaceForce force = push(*pick, ray.direction, 2000.0);

  DeformationRequest by_server;
  by_server.vertex_constraints = clamp_first_rows(n);
  by_server.surface_forces.push_back(force);
  DeformationRequest by_client;
  by_client.vertex_constraints = clamp_first_rows(n);
  by_client.forces = spread_force(ev, force).value();
  const auto a = session.deform(id, by_server).value();
  const auto b = session.deform(id, by_client).value();
  double max_displacement = 0.0, max_difference = 0.0;
  for (size_t i = 0; i < a.positions.size(); ++i) {
    max_displacement = std::max(max_displacement, (a.positions[i] - mesh.positions()[i]).norm());
    max_difference = std::max(max_difference, (a.positions[i] - b.positions[i]).norm());
  }
  EXPECT_GT(max_displacement, 1e-4);
  EXPECT_LT(max_difference, 1e-9 * max_displacement);
  // The pushed point moves along the push.
  EXPECT_LT((ev.evaluate(pick->point, a.positions).position - pick->position).z(), 0.0);
}

// The floor of paper Section 6.2: what touches it is held, so a grab elsewhere is a determined
// system; a single contact point leaves rotations free and the server says so.
TEST(EndToEnd, FloorHoldsWhatTouchesIt) {
  EmbeddedSession session;
  const ControlMesh cube = test::load_asset_mesh("catmark_cube.obj");
  const double size = cube.bounding_diagonal();
  const GeomId id = session.upload(cube, shell_material()).value().id;
  const LimitEvaluator ev = LimitEvaluator::create(cube).value();
  const Tessellation surface = Tessellation::create(ev, 4).value();
  double lowest = std::numeric_limits<double>::infinity(), highest = -lowest;
  for (const Vec3& x : surface.vertices()) {
    lowest = std::min(lowest, x.y());
    highest = std::max(highest, x.y());
  }
  const Plane floor{Vec3(0, lowest, 0), Vec3::UnitY()};
  FloorOptions loose;
  loose.tolerance = 0.05 * size;
  const FloorContact contact = floor_contact(surface, floor, loose).value();
  ASSERT_TRUE(contact.fixes_rigid_motion);

  // Grab the top and pull it up.
  const Picker picker = Picker::create(surface).value();
  const auto pick = picker.pick({Vec3(0.05, highest + 1.0, 0.02), Vec3(0, -1, 0)}).value();
  ASSERT_TRUE(pick.has_value());
  const Pose hand{Vec3(0, highest + 1.0, 0), Eigen::Quaterniond::Identity()};
  const Grab grab = Grab::begin(ev, pick->point, cube.positions(), hand).value();
  Pose lifted = hand;
  lifted.position.y() += 0.02 * size;
  DeformationRequest request;
  contact.add_to(request);
  request.limit_constraints.push_back(grab.constraint(lifted));
  const DeformationResult result = session.deform(id, request).value();
  EXPECT_LT((ev.evaluate(pick->point, result.positions).position - grab.target(lifted)).norm(), 1e-9 * size);
  for (const SurfacePoint& p : contact.points) {
    EXPECT_LT((ev.evaluate(p, result.positions).position - ev.evaluate(p).position).norm(), 1e-9 * size);
  }

  // One contact point: the cube could still turn about the line through it and the grab.
  FloorOptions tight;
  tight.tolerance = 1e-9;
  const FloorContact single = floor_contact(surface, floor, tight).value();
  ASSERT_FALSE(single.fixes_rigid_motion);
  DeformationRequest undetermined;
  single.add_to(undetermined);
  undetermined.limit_constraints.push_back(grab.constraint(lifted));
  const auto refused = session.deform(id, undetermined);
  ASSERT_FALSE(refused.ok());
  EXPECT_EQ(refused.error().code, ErrorCode::kUnprocessable);
}

// Paper Fig. 5 on a plate: one control point displaced (and the clamped edge) on the coarse mesh
// and, carried by the control point correspondence, on the refined mesh: the limit surfaces agree
// closely away from the constraint, although they have different DOF. A limit constraint gives
// its exact target on every level.
TEST(EndToEnd, LevelsOfDetailAgreeAndLimitConstraintsAreExactOnEveryLevel) {
  EmbeddedSession session;
  const int n = 4;
  const ControlMesh coarse = curved_plate(n);
  const MeshRefinement refinement = MeshRefinement::create(coarse, 1).value();
  const GeomId coarse_id = session.upload(coarse, shell_material()).value().id;
  const GeomId fine_id = session.upload(refinement.fine(), shell_material()).value().id;
  const LimitEvaluator coarse_ev = LimitEvaluator::create(coarse).value();
  const LimitEvaluator fine_ev = LimitEvaluator::create(refinement.fine()).value();

  // Displacement constraint on the middle of the free edge (control point (2, 4)), 5 cm up.
  DeformationRequest request;
  request.vertex_constraints = clamp_first_rows(n);
  const double lift = 0.05;
  request.vertex_constraints.push_back({test::grid_index(n, n / 2, n), kAxisZ, Vec3(0, 0, lift)});
  const DeformationRequest fine_request = refinement.request_to_fine(request).value();
  const auto coarse_result = session.deform(coarse_id, request).value();
  const auto fine_result = session.deform(fine_id, fine_request).value();

  // Compare the two deformed limit surfaces on a grid of points away from the constrained one.
  const Vec3 constrained = coarse.positions()[static_cast<size_t>(test::grid_index(n, n / 2, n))];
  double worst = 0.0, largest = 0.0;
  for (int f = 0; f < coarse.num_faces(); ++f) {
    for (double u : {0.25, 0.75}) {
      for (double v : {0.25, 0.75}) {
        const SurfacePoint p{f, 0, u, v};
        const Vec3 rest = coarse_ev.evaluate(p).position;
        if ((rest - constrained).head<2>().norm() < 0.3) continue;
        const Vec3 a = coarse_ev.evaluate(p, coarse_result.positions).position - rest;
        const Vec3 b = fine_ev.evaluate(refinement.fine_point(p).value(), fine_result.positions).position - rest;
        worst = std::max(worst, (a - b).norm());
        largest = std::max(largest, a.norm());
      }
    }
  }
  RecordProperty("fig5_relative_difference", std::to_string(worst / largest));
  EXPECT_GT(largest, 0.1 * lift);      // the constraint moved the surface there
  EXPECT_LT(worst, 0.25 * largest);    // ... in nearly the same way on both levels

  // A limit constraint at a point of the coarse surface: exact on both levels.
  const LimitConstraint target{{9, 0, 0.3, 0.6}, Vec3(0.0, 0.01, 0.04), std::nullopt, std::nullopt};
  DeformationRequest limit_request;
  limit_request.vertex_constraints = clamp_first_rows(n);
  limit_request.limit_constraints.push_back(target);
  const auto c = session.deform(coarse_id, limit_request).value();
  const auto f = session.deform(fine_id, refinement.request_to_fine(limit_request).value()).value();
  const Vec3 goal = coarse_ev.evaluate(target.point).position + target.displacement;
  EXPECT_LT((coarse_ev.evaluate(target.point, c.positions).position - goal).norm(), 1e-9);
  EXPECT_LT((fine_ev.evaluate(refinement.fine_point(target.point).value(), f.positions).position - goal).norm(), 1e-9);
}

// The paper's parallel simulation through a real server: coarse first (or dropped if the fine one
// is already there), then fine, both with the limit constraint exact.
TEST(EndToEnd, ParallelLevelsDeliverCoarseThenFine) {
  EmbeddedSession session;
  const int n = 4;
  const ControlMesh coarse = curved_plate(n);
  auto levels = ParallelLevels::create(session, coarse, shell_material(), 2).value();
  const LimitEvaluator coarse_ev = LimitEvaluator::create(coarse).value();
  const LimitEvaluator fine_ev = LimitEvaluator::create(levels->refinement().fine()).value();

  DeformationRequest request;
  request.vertex_constraints = clamp_first_rows(n);
  const LimitConstraint target{{13, 0, 0.5, 0.5}, Vec3(0.0, 0.0, 0.03), std::nullopt, std::nullopt};
  request.limit_constraints.push_back(target);
  const Vec3 goal = coarse_ev.evaluate(target.point).position + target.displacement;
  const uint64_t submission = levels->submit(request).value();

  std::vector<LevelResult> delivered;
  const auto deadline = std::chrono::steady_clock::now() + std::chrono::seconds(120);
  while ((delivered.empty() || !delivered.back().fine) && std::chrono::steady_clock::now() < deadline) {
    if (auto r = levels->wait(std::chrono::milliseconds(100))) delivered.push_back(std::move(*r));
  }
  ASSERT_FALSE(delivered.empty());
  ASSERT_TRUE(delivered.back().fine);
  ASSERT_LE(delivered.size(), 2u);
  if (delivered.size() == 2) {
    EXPECT_FALSE(delivered.front().fine);
  }
  for (const LevelResult& r : delivered) {
    EXPECT_EQ(r.submission, submission);
    const DeformationResult& d = r.result.value();
    const Vec3 x = r.fine ? fine_ev.evaluate(levels->refinement().fine_point(target.point).value(), d.positions).position
                          : coarse_ev.evaluate(target.point, d.positions).position;
    EXPECT_LT((x - goal).norm(), 1e-9) << (r.fine ? "fine" : "coarse");
  }
  EXPECT_EQ(levels->in_flight(), 0u);
}

}  // namespace
}  // namespace softshell
