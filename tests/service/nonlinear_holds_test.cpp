// Nonlinear hold states (PROTOCOL.md version 2, "The nonlinear model"): the hold state is solved
// with the nonlinear model while any live hold asks for it, warm-started from its previous
// nonlinear answer; checked against rigid motions (no strain) and the linear limit of small loads,
// and for refusals (422, the state stays) and the way back to the linear model.
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>

#include <Eigen/Geometry>

#include "server_test_support.h"
#include "service_test_support.h"
#include "softshell/service/service.h"

namespace softshell::service {
namespace {

using test::small_options;
using test::upload_ready;

using test::exact_grid;
using test::exact_material;
using test::grid_index;
using std::chrono::milliseconds;

constexpr int kN = 4;  // exact_grid(4): 4 x 4 faces over [0, 1]^2, 25 control points

Result<HoldOutcome> outcome(const HoldTicket& t) {
  if (t.outcome.wait_for(std::chrono::seconds(60)) != std::future_status::ready) {
    ADD_FAILURE() << "hold " << t.hold_id << " version " << t.version << " was not answered";
    return Error{ErrorCode::kUnavailable, "timeout"};
  }
  return t.outcome.get();
}

// The answer of a PUT (its error if refused).
Result<ResultPtr> put(Service& s, const GeomId& id, const std::string& hold, DeformationRequest r) {
  auto t = s.put_hold(id, hold, std::move(r));
  if (!t) return t.error();
  auto out = outcome(*t);
  if (!out) return out.error();
  return out->result;
}

DeformationRequest nonlinear(DeformationRequest r) {
  r.model = DeformationModel::kNonlinear;
  return r;
}

// The two columns x = 0 and x = 1/4 turned rigidly by `degrees` about the y axis (the edge x = 0):
// a clamp that turns that edge of the plate.
DeformationRequest turn_edge(double degrees) {
  const ControlMesh mesh = exact_grid(kN);
  const Eigen::Matrix3d r = Eigen::AngleAxisd(degrees * M_PI / 180.0, Vec3::UnitY()).toRotationMatrix();
  DeformationRequest out;
  for (int j = 0; j <= kN; ++j) {
    for (int i = 0; i <= 1; ++i) {
      const int32_t k = grid_index(kN, i, j);
      const Vec3& x = mesh.positions()[static_cast<size_t>(k)];
      out.vertex_constraints.push_back({k, kAxisAll, r * x - x});
    }
  }
  return out;
}

// Largest distance of a result's control points from the whole plate turned rigidly like the
// clamped edge.
double off_rigid(const StoredResult& result, double degrees) {
  const ControlMesh mesh = exact_grid(kN);
  const Eigen::Matrix3d r = Eigen::AngleAxisd(degrees * M_PI / 180.0, Vec3::UnitY()).toRotationMatrix();
  double worst = 0.0;
  for (size_t i = 0; i < mesh.positions().size(); ++i) {
    worst = std::max(worst, (result.positions[i] - r * mesh.positions()[i]).norm());
  }
  return worst;
}

// Largest relative change of length over the control mesh's edges (0 for a rigid motion).
double stretch(const StoredResult& result) {
  const ControlMesh mesh = exact_grid(kN);
  double worst = 0.0;
  for (int j = 0; j <= kN; ++j) {
    for (int i = 0; i <= kN; ++i) {
      const size_t a = static_cast<size_t>(grid_index(kN, i, j));
      for (const auto& [di, dj] : {std::pair{1, 0}, std::pair{0, 1}}) {
        if (i + di > kN || j + dj > kN) continue;
        const size_t b = static_cast<size_t>(grid_index(kN, i + di, j + dj));
        const double rest = (mesh.positions()[b] - mesh.positions()[a]).norm();
        const double now = (result.positions[b] - result.positions[a]).norm();
        worst = std::max(worst, std::abs(now - rest) / rest);
      }
    }
  }
  return worst;
}

double max_difference(const StoredResult& a, const StoredResult& b) {
  double worst = 0.0;
  for (size_t i = 0; i < a.positions.size(); ++i) worst = std::max(worst, (a.positions[i] - b.positions[i]).norm());
  return worst;
}

double max_motion(const StoredResult& a) {
  const ControlMesh mesh = exact_grid(kN);
  double worst = 0.0;
  for (size_t i = 0; i < a.positions.size(); ++i) worst = std::max(worst, (a.positions[i] - mesh.positions()[i]).norm());
  return worst;
}

// An edge of a free plate turned by 30 and then 90 degrees through a nonlinear hold: the rest of
// the plate follows rigidly (no strain: control-mesh edge lengths kept, stresses ~0), where the
// linear hold state stretches the plate by tens of percent. A drag (90 -> 92 degrees) starts
// from the previous answer: fewer iterations than the same request from rest, same answer.
TEST(NonlinearHoldsTest, TurningAnEdgeTurnsTheWholePlateRigidly) {
  Service s(small_options());
  const GeomId id = upload_ready(s, exact_grid(kN));
  for (double degrees : {30.0, 90.0}) {
    auto held = put(s, id, "edge", nonlinear(turn_edge(degrees)));
    ASSERT_TRUE(held && *held) << (held ? "no result" : held.error().message);
    const StoredResult& r = **held;
    ASSERT_TRUE(r.nonlinear);
    EXPECT_EQ(r.request.model, DeformationModel::kNonlinear);
    EXPECT_EQ(r.to_result().model, DeformationModel::kNonlinear);
    EXPECT_LT(r.nonlinear->residual, 1e-8);
    EXPECT_LT(off_rigid(r, degrees), 1e-6) << degrees << " degrees";
    EXPECT_LT(stretch(r), 1e-6) << degrees << " degrees";
  }
  // The same clamp with the linear model: the plate is stretched (the paper's limitation).
  auto linear = put(s, id, "edge", turn_edge(90.0));
  ASSERT_TRUE(linear && *linear) << (linear ? "no result" : linear.error().message);
  EXPECT_FALSE((*linear)->nonlinear);
  EXPECT_EQ((*linear)->request.model, DeformationModel::kLinear);
  EXPECT_GT(off_rigid(**linear, 90.0), 0.3);
  EXPECT_GT(stretch(**linear), 0.2);

  // Back to nonlinear (from rest: the state was linear), then a small drag step from there.
  auto at90 = put(s, id, "edge", nonlinear(turn_edge(90.0)));
  ASSERT_TRUE(at90 && *at90);
  EXPECT_LT(off_rigid(**at90, 90.0), 1e-6);
  auto dragged = put(s, id, "edge", nonlinear(turn_edge(92.0)));
  ASSERT_TRUE(dragged && *dragged) << (dragged ? "no result" : dragged.error().message);
  auto from_rest = s.deform(id, nonlinear(turn_edge(92.0))).get();
  ASSERT_TRUE(from_rest) << from_rest.error().message;
  EXPECT_LT(off_rigid(**dragged, 92.0), 1e-6);
  EXPECT_LT(max_difference(**dragged, **from_rest), 1e-6);
  EXPECT_LT((*dragged)->nonlinear->iterations, (*from_rest)->nonlinear->iterations);

  // Stresses of a nonlinear hold result come from the Green-Lagrange strains: ~0 for the rigid
  // turn, while the linear result of the same clamp reads the turn as strain.
  StressQuery points;
  points.points = {{0, 0, 0.5, 0.5}, {10, 0, 0.25, 0.75}, {15, 0, 0.5, 0.5}};
  auto rigid = s.stresses(id, (*dragged)->res_id, points);
  auto stretched = s.stresses(id, (*linear)->res_id, points);
  ASSERT_TRUE(rigid && stretched) << (rigid ? stretched.error().message : rigid.error().message);
  EXPECT_GT(stretched->max.von_mises(), 1e4);  // Pa
  EXPECT_LT(rigid->max.von_mises(), 1e-6 * stretched->max.von_mises());
}

// A small load through a nonlinear hold gives the linear answer to first order, and the
// difference has the orders the plate's physics says: the linear model moves a flat plate under a
// transverse load only across (in-plane motion exactly 0), the nonlinear one also draws it in, by
// the square of the deflection (relative to the motion: linear in the load); and the deflection is
// odd in the load, so its nonlinear correction is cubic (relative: quadratic).
TEST(NonlinearHoldsTest, SmallNonlinearHoldAgreesWithTheLinearOneToFirstOrder) {
  Service s(small_options());
  const GeomId id = upload_ready(s, exact_grid(kN));
  DeformationRequest pins;
  pins.vertex_constraints = test::pinned_corners(kN);
  ASSERT_TRUE(put(s, id, "pins", pins));  // linear: the state is nonlinear when any hold asks
  std::vector<double> in_plane, across;
  for (double fz : {-0.0025, -0.005}) {
    DeformationRequest push;
    push.forces.push_back({grid_index(kN, kN / 2, kN / 2), Vec3(0.0, 0.0, fz)});
    auto lin = put(s, id, "push", push);
    auto non = put(s, id, "push", nonlinear(push));
    ASSERT_TRUE(lin && *lin && non && *non) << (non ? "" : non.error().message);
    EXPECT_FALSE((*lin)->nonlinear);
    ASSERT_TRUE((*non)->nonlinear);
    EXPECT_EQ((*non)->request.model, DeformationModel::kNonlinear);
    EXPECT_EQ((*non)->request.vertex_constraints.size(), 4u);  // the linear hold's pins are in it
    EXPECT_LT((*non)->nonlinear->residual, 1e-8);
    const double motion = max_motion(**lin);
    double lin_in_plane = 0.0, d_in_plane = 0.0, d_across = 0.0;
    const ControlMesh mesh = exact_grid(kN);
    for (size_t i = 0; i < mesh.positions().size(); ++i) {
      const Vec3 d = (*non)->positions[i] - (*lin)->positions[i];
      lin_in_plane = std::max(lin_in_plane, ((*lin)->positions[i] - mesh.positions()[i]).head<2>().norm());
      d_in_plane = std::max(d_in_plane, d.head<2>().norm());
      d_across = std::max(d_across, std::abs(d.z()));
    }
    EXPECT_LT(lin_in_plane, 1e-12 * motion);
    EXPECT_LT(d_in_plane, 0.01 * motion);
    EXPECT_LT(d_across, 0.01 * motion);
    in_plane.push_back(d_in_plane / motion);
    across.push_back(d_across / motion);
  }
  const double order_in_plane = std::log2(in_plane[1] / in_plane[0]);
  const double order_across = std::log2(across[1] / across[0]);
  EXPECT_NEAR(order_in_plane, 1.0, 0.15) << in_plane[0] << " " << in_plane[1];
  EXPECT_NEAR(order_across, 2.0, 0.15) << across[0] << " " << across[1];
}

// When the last hold that asks for the nonlinear model is released (or changed back), the state
// is solved linearly again: the answer is the linear solve of the remaining holds, exactly.
TEST(NonlinearHoldsTest, ReleasingTheLastNonlinearHoldGoesBackToLinear) {
  Service s(small_options());
  const GeomId id = upload_ready(s, exact_grid(kN));
  ASSERT_TRUE(put(s, id, "pins", test::pinned_push(1, kN)));  // corners pinned and a push, linear
  DeformationRequest grab;
  grab.limit_constraints.push_back({{5, 0, 0.5, 0.5}, Vec3(0.0, 0.0, 0.3), std::nullopt, std::nullopt});
  auto both = put(s, id, "grab", nonlinear(grab));
  ASSERT_TRUE(both && *both) << (both ? "" : both.error().message);
  ASSERT_TRUE((*both)->nonlinear);
  auto released = s.release_hold(id, "grab");
  ASSERT_TRUE(released);
  auto after = outcome(*released);
  ASSERT_TRUE(after && after->result) << (after ? "no result" : after.error().message);
  const StoredResult& r = *after->result;
  EXPECT_FALSE(r.nonlinear);
  EXPECT_EQ(r.request.model, DeformationModel::kLinear);
  auto alone = s.deform(id, test::pinned_push(1, kN)).get();
  ASSERT_TRUE(alone);
  EXPECT_LT(max_difference(r, **alone), 1e-12);
  EXPECT_GT(max_difference(r, **both), 1e-2);
}

// A nonlinear hold the solver cannot bring to equilibrium within its limits is a 422 with the
// solver's message; the hold keeps its previous contents and no result is stored.
TEST(NonlinearHoldsTest, UnconvergedNonlinearHoldIsRefusedAndTheStateStays) {
  ServiceOptions o = small_options();
  o.nonlinear.max_iterations = 3;  // so that a large pull cannot converge
  Service s(o);
  const GeomId id = upload_ready(s, exact_grid(kN));
  DeformationRequest pins;
  pins.vertex_constraints = test::pinned_corners(kN);
  auto first = put(s, id, "pins", pins);
  DeformationRequest small;
  small.limit_constraints.push_back({{5, 0, 0.5, 0.5}, Vec3(0.0, 0.0, 0.01), std::nullopt, std::nullopt});
  auto second = put(s, id, "grab", small);
  ASSERT_TRUE(first && second && *second);
  DeformationRequest far = small;
  far.limit_constraints[0].displacement = Vec3(-0.3, 0.2, 0.6);
  auto refused = put(s, id, "grab", nonlinear(far));
  ASSERT_FALSE(refused);
  EXPECT_EQ(refused.error().code, ErrorCode::kUnprocessable);
  EXPECT_NE(refused.error().message.find("equilibrium"), std::string::npos) << refused.error().message;
  EXPECT_NE(refused.error().message.find("keeps its previous contents (version 1)"), std::string::npos)
      << refused.error().message;
  auto detail = s.hold(id, "grab");
  ASSERT_TRUE(detail);
  EXPECT_EQ(detail->info.version, 1u);
  EXPECT_EQ(detail->request.model, DeformationModel::kLinear);
  auto list = s.holds(id);
  ASSERT_TRUE(list);
  EXPECT_EQ(list->res_id, (*second)->res_id);
  EXPECT_EQ(list->state, HoldStateStatus::kSolved);
  auto latest = s.latest_result(id, 0, milliseconds(0));
  ASSERT_TRUE(latest && *latest);
  EXPECT_EQ((*latest)->res_id, (*second)->res_id);
  // A new hold refused the same way is not created.
  DeformationRequest elsewhere = far;
  elsewhere.limit_constraints[0].point = {10, 0, 0.5, 0.5};
  auto other = put(s, id, "other", nonlinear(elsewhere));
  ASSERT_FALSE(other);
  EXPECT_EQ(other.error().code, ErrorCode::kUnprocessable);
  EXPECT_FALSE(s.hold(id, "other"));
}

}  // namespace
}  // namespace softshell::service
