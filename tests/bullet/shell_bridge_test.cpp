#include "softshell/bullet/shell_bridge.h"

#include <atomic>
#include <cmath>
#include <cstdio>
#include <functional>
#include <numbers>

#include <gtest/gtest.h>

#include "bullet_world.h"
#include "softshell/embedded_session.h"
#include "test_meshes.h"
#include "test_sessions.h"

namespace softshell::bullet {
namespace {

using namespace std::chrono_literals;

// The real in-process server.
std::shared_ptr<Session> make_session() { return std::make_shared<EmbeddedSession>(); }

constexpr double kGravity = 9.81;
constexpr double kStep = 1.0 / 120.0;

// A 1 m x 1 m plastic plate (E = 2 GPa, t = 5 mm), 12 x 12 faces, every boundary control point
// fixed. Locally it lies in z = 0 over [0, 1]^2; in the world it is centred at the origin, either
// in the z = 0 plane of a z-up world or (y_up) in the y = 0 plane of a y-up world.
struct Plate {
  static constexpr int kN = 12;
  ControlMesh mesh = test::make_grid(kN, kN, 1.0, 1.0);
  Material material{2.0e9, 0.35, 0.005, 1200.0};
  bool y_up = false;

  btTransform placement() const {
    btTransform t;
    t.setIdentity();
    if (y_up) {
      t.setRotation(btQuaternion(btVector3(1, 0, 0), -SIMD_HALF_PI));  // local z -> world y
      t.setOrigin(btVector3(-0.5f, 0.0f, 0.5f));
    } else {
      t.setOrigin(btVector3(-0.5f, -0.5f, 0.0f));
    }
    return t;
  }
  btVector3 up() const { return y_up ? btVector3(0, 1, 0) : btVector3(0, 0, 1); }

  ShellSettings settings() const {
    ShellSettings s;
    s.mesh.level = 2;
    s.max_request_rate = 0.0;  // the tests pace themselves
    s.transform = placement();
    for (int j = 0; j <= kN; ++j) {
      for (int i = 0; i <= kN; ++i) {
        if (i == 0 || j == 0 || i == kN || j == kN) {
          s.supports.vertex_constraints.push_back({test::grid_index(kN, i, j), kAxisAll, Vec3::Zero()});
        }
      }
    }
    return s;
  }
};

Vec3 total_force(const DeformationRequest& request) {
  Vec3 sum = Vec3::Zero();
  for (const PointForce& f : request.forces) sum += f.force;
  return sum;
}

Vec3 to_vec(const btVector3& v) { return Vec3(v.x(), v.y(), v.z()); }
btVector3 to_bt(const Vec3& v) { return btVector3(float(v.x()), float(v.y()), float(v.z())); }

// Steps the world and the bridge in lockstep: each step's request is answered and applied before
// the next step, so every run sees the same sequence of shapes. (The asynchronous, real-time
// behaviour is tested against a slowed server.)
void lockstep(test::BulletWorld& scene, ShellBridge& bridge, int steps, const std::function<void()>& each = {}) {
  for (int step = 0; step < steps; ++step) {
    scene.world.stepSimulation(static_cast<btScalar>(kStep), 1, static_cast<btScalar>(kStep));
    bridge.update();
    ASSERT_TRUE(bridge.wait_idle(10s).ok());
    if (each) each();
  }
}

// What a sphere dropped on the plate did, once at rest. Positions and displacements are in the
// plate's local frame (z = its normal).
struct DropOutcome {
  int32_t max_contacts = 0;
  Vec3 sent_force = Vec3::Zero();          // total force of the last request sent (local frame, N)
  double max_deflection = 0.0;             // largest displacement of the limit surface along -z (m)
  Vec3 max_deflection_at = Vec3::Zero();   // where (rest position)
  Vec3 contact_point = Vec3::Zero();       // where the sphere touches
  double contact_deflection = 0.0;         // limit-surface displacement along -z under the sphere (m)
  ShellStats stats;
};

using Inspect = std::function<void(test::BulletWorld&, ShellBridge&, ShellId, btRigidBody& sphere)>;

DropOutcome drop_sphere(double mass, bool y_up = false, const Inspect& inspect = {}) {
  const double radius = 0.05;
  Plate plate;
  plate.y_up = y_up;
  test::BulletWorld scene(-kGravity * plate.up());
  ShellBridge bridge(scene.world);
  auto shell = bridge.add_shell(make_session(), plate.mesh, plate.material, plate.settings());
  EXPECT_TRUE(shell.ok()) << shell.error().message;
  btRigidBody* sphere = scene.add_sphere(radius, mass, plate.up() * static_cast<btScalar>(radius + 0.03));
  sphere->setDamping(0.2f, 0.6f);
  sphere->setActivationState(DISABLE_DEACTIVATION);

  DropOutcome out;
  lockstep(scene, bridge, 360, [&] { out.max_contacts = std::max(out.max_contacts, bridge.stats(*shell).contacts); });

  out.stats = bridge.stats(*shell);
  const DeformationRequest* sent = bridge.last_sent_request(*shell);
  EXPECT_NE(sent, nullptr);
  if (sent) out.sent_force = total_force(*sent);
  const auto& contacts = bridge.contacts(*shell);
  EXPECT_FALSE(contacts.empty());
  const btTransform placement = plate.placement();
  if (!contacts.empty()) out.contact_point = to_vec(placement.invXform(to_bt(contacts.front().position)));

  // Deflection of the limit surface: tessellation vertices now vs rest.
  const auto& now = bridge.collision_mesh(*shell).tessellation().vertices();
  const auto rest = Tessellation::create(LimitEvaluator::create(plate.mesh).value(), 2).value();
  double best_distance = 1e9;
  for (size_t i = 0; i < now.size(); ++i) {
    const double dz = now[i].z() - rest.vertices()[i].z();
    if (-dz > out.max_deflection) {
      out.max_deflection = -dz;
      out.max_deflection_at = rest.vertices()[i];
    }
    const double d = (rest.vertices()[i] - out.contact_point).head<2>().norm();
    if (d < best_distance) {
      best_distance = d;
      out.contact_deflection = -dz;
    }
  }
  if (inspect) inspect(scene, bridge, *shell, *sphere);
  return out;
}

void expect_dent_under_the_sphere(const DropOutcome& drop, double mass) {
  EXPECT_GT(drop.max_contacts, 0);
  EXPECT_GT(drop.stats.results_applied, 0u);
  EXPECT_FALSE(drop.stats.last_error) << drop.stats.last_error->message;
  EXPECT_EQ(drop.stats.channel.failed, 0u);

  // At rest the force sent is the sphere's weight (down along the plate's normal).
  const Vec3 weight(0.0, 0.0, -mass * kGravity);
  EXPECT_LT((drop.sent_force - weight).norm(), 0.05 * weight.norm())
      << "sent " << drop.sent_force.transpose() << ", weight " << weight.transpose();

  // The plate deflects down under the sphere, most near the contact.
  EXPECT_GT(drop.contact_deflection, 0.0);
  EXPECT_GT(drop.contact_deflection, 0.8 * drop.max_deflection);
  EXPECT_LT((drop.max_deflection_at - drop.contact_point).head<2>().norm(), 0.1)
      << "largest deflection at " << drop.max_deflection_at.transpose() << ", contact at "
      << drop.contact_point.transpose();
  // Order of magnitude of a point-loaded Kirchhoff plate (0.0056 .. 0.0116 P a^2 / D).
  const double D = 2.0e9 * std::pow(0.005, 3) / (12.0 * (1.0 - 0.35 * 0.35));
  EXPECT_GT(drop.max_deflection, 0.3 * 0.0056 * mass * kGravity / D);
  EXPECT_LT(drop.max_deflection, 3.0 * 0.0116 * mass * kGravity / D);
}

TEST(ShellBridge, SphereOnPlateDentsItAndSendsItsWeight) {
  const double mass = 1.0;
  const DropOutcome drop = drop_sphere(mass, false, [&](test::BulletWorld& scene, ShellBridge& bridge, ShellId shell,
                                                         btRigidBody& sphere) {
    // The sphere sits in the dent: lower than on the flat plate by about the dent's depth.
    const double sunk = 0.05 - static_cast<double>(sphere.getWorldTransform().getOrigin().z());
    const auto& contacts = bridge.contacts(shell);
    ASSERT_FALSE(contacts.empty());
    EXPECT_GT(sunk, 0.0);

    // A ray through Bullet (shells only: their filter group) hits the deformed surface, not the
    // rest plane: the limit surface of the deformed control points at the hit's (face, u, v).
    const Vec3 at = contacts.front().position;
    const btVector3 from(float(at.x()), float(at.y()), 1.0f), to(float(at.x()), float(at.y()), -1.0f);
    struct Callback : btCollisionWorld::ClosestRayResultCallback {
      using ClosestRayResultCallback::ClosestRayResultCallback;
      int triangle = -1;
      btScalar addSingleResult(btCollisionWorld::LocalRayResult& result, bool normal_in_world) override {
        if (result.m_localShapeInfo) triangle = result.m_localShapeInfo->m_triangleIndex;
        return ClosestRayResultCallback::addSingleResult(result, normal_in_world);
      }
    } hit(from, to);
    hit.m_collisionFilterMask = btBroadphaseProxy::StaticFilter;
    scene.world.rayTest(from, to, hit);
    ASSERT_TRUE(hit.hasHit());
    EXPECT_EQ(hit.m_collisionObject, &bridge.collision_object(shell));
    const double hit_z = hit.m_hitPointWorld.z();
    EXPECT_LT(hit_z, -0.5 * sunk);
    EXPECT_NEAR(hit_z, contacts.front().position.z(), 1e-3);
    const CollisionMesh& mesh = bridge.collision_mesh(shell);
    const Vec3 local = to_vec(bridge.collision_object(shell).getWorldTransform().invXform(hit.m_hitPointWorld));
    const SurfacePoint p = mesh.surface_point(hit.triangle, local);
    const auto evaluator = LimitEvaluator::create(Plate{}.mesh).value();
    const Vec3 limit = evaluator.evaluate(p, bridge.control_positions(shell)).position;
    EXPECT_LT((limit - local).norm(), 2e-4) << "hit " << local.transpose() << " limit " << limit.transpose();
  });
  expect_dent_under_the_sphere(drop, mass);
}

// The background mesh updates run where the host says: each on its executor (counted here), and
// with an InlineExecutor inside update() itself, with the same deflection either way.
TEST(ShellBridge, BackgroundMeshUpdatesRunOnTheHostsExecutor) {
  struct CountingExecutor final : Executor {
    ThreadPool pool{1};
    std::atomic<int> posted{0};
    void post(std::function<void()> task) override {
      ++posted;
      pool.post(std::move(task));
    }
    int concurrency() const override { return 1; }
  };
  auto run = [](std::shared_ptr<Executor> executor) {
    Plate plate;
    test::BulletWorld scene(-kGravity * plate.up());
    ShellBridge bridge(scene.world, std::move(executor));
    const ShellId shell = bridge.add_shell(make_session(), plate.mesh, plate.material, plate.settings()).value();
    btRigidBody* sphere = scene.add_sphere(0.05, 1.0, plate.up() * static_cast<btScalar>(0.08));
    sphere->setActivationState(DISABLE_DEACTIVATION);
    lockstep(scene, bridge, 240);
    const ShellStats stats = bridge.stats(shell);
    EXPECT_GT(stats.results_applied, 0u);
    EXPECT_FALSE(stats.last_error.has_value()) << stats.last_error->message;
    double deflection = 0.0;
    const auto rest = Tessellation::create(LimitEvaluator::create(plate.mesh).value(), 2).value();
    const auto& now = bridge.collision_mesh(shell).tessellation().vertices();
    for (size_t i = 0; i < now.size(); ++i) deflection = std::max(deflection, rest.vertices()[i].z() - now[i].z());
    return std::make_pair(stats.results_applied, deflection);
  };
  auto counting = std::make_shared<CountingExecutor>();
  const auto [applied, deflection] = run(counting);
  EXPECT_GT(counting->posted.load(), 0);
  EXPECT_LE(counting->posted.load(), static_cast<int>(applied));  // one task per burst of results, never more
  const auto [inline_applied, inline_deflection] = run(std::make_shared<InlineExecutor>());
  EXPECT_GT(inline_applied, 0u);
  EXPECT_GT(deflection, 0.0);
  EXPECT_NEAR(inline_deflection, deflection, 0.05 * deflection);
}

TEST(ShellBridge, WorksInTheShellsOwnFrame) {
  // The same plate standing in a y-up world: forces go to the server in the plate's local frame.
  const double mass = 1.0;
  expect_dent_under_the_sphere(drop_sphere(mass, true), mass);
}

TEST(ShellBridge, TwiceTheMassGivesTwiceTheDeflection) {
  const DropOutcome one = drop_sphere(1.0);
  const DropOutcome two = drop_sphere(2.0);
  ASSERT_GT(one.max_deflection, 0.0);
  EXPECT_NEAR(two.max_deflection / one.max_deflection, 2.0, 0.1)
      << one.max_deflection << " vs " << two.max_deflection;
  EXPECT_NEAR(two.contact_deflection / one.contact_deflection, 2.0, 0.1);
}

TEST(ShellBridge, SleepingBodiesKeepPressingAndTheShellSpringsBackWhenTheyLeave) {
  Plate plate;
  test::BulletWorld scene(-kGravity * plate.up());
  ShellBridge bridge(scene.world);
  const ShellId shell = bridge.add_shell(make_session(), plate.mesh, plate.material, plate.settings()).value();
  btRigidBody* sphere = scene.add_sphere(0.05, 1.0, btVector3(0.0f, 0.0f, 0.08f));
  sphere->setDamping(0.3f, 0.8f);

  // Long enough for Bullet to put the resting sphere to sleep (2 s without motion).
  bool slept = false;
  lockstep(scene, bridge, 600, [&] { slept = slept || !sphere->isActive(); });
  EXPECT_TRUE(slept);
  const size_t centre = size_t(test::grid_index(Plate::kN, Plate::kN / 2, Plate::kN / 2));
  const double dent = plate.mesh.positions()[centre].z() - bridge.control_positions(shell)[centre].z();
  EXPECT_GT(dent, 1e-3);
  const DeformationRequest* sent = bridge.last_sent_request(shell);
  ASSERT_NE(sent, nullptr);
  EXPECT_NEAR(total_force(*sent).z(), -kGravity, 0.05 * kGravity);

  // The sphere is taken away: the forces fade out and the plate comes back to its rest shape.
  scene.world.removeRigidBody(sphere);
  lockstep(scene, bridge, 240);
  sent = bridge.last_sent_request(shell);
  ASSERT_NE(sent, nullptr);
  EXPECT_TRUE(sent->forces.empty());
  EXPECT_EQ(bridge.stats(shell).contacts, 0);
  for (size_t i = 0; i < plate.mesh.positions().size(); ++i) {
    EXPECT_LT((bridge.control_positions(shell)[i] - plate.mesh.positions()[i]).norm(), 1e-9);
  }
  scene.world.addRigidBody(sphere);  // BulletWorld removes it again
}

// An arch lying on the floor (z = 0): z = 0.3 sin(pi x) over [0, 1] x [0, 0.6], its straight
// edges on the floor, no other support; a box rests on its crown.
struct ArchScene {
  ControlMesh mesh = test::make_grid(8, 4, 1.0, 0.6, [](double x, double) { return 0.3 * std::sin(std::numbers::pi * x); });
  Material material{2.0e9, 0.35, 0.005, 1200.0};
  test::BulletWorld scene;
  std::unique_ptr<ShellBridge> bridge = std::make_unique<ShellBridge>(scene.world);
  ShellId shell;

  explicit ArchScene(bool floor, FloorHold hold = FloorHold::kControlPoints) {
    ShellSettings s;
    s.mesh.level = 2;
    s.max_request_rate = 0.0;
    s.floor.enabled = floor;
    s.floor.normal = Vec3::UnitZ();
    s.floor.hold = hold;
    shell = bridge->add_shell(make_session(), mesh, material, s).value();
    btRigidBody* box = scene.add_box(btVector3(0.05f, 0.05f, 0.05f), 2.0, btVector3(0.5f, 0.3f, 0.36f));
    box->setActivationState(DISABLE_DEACTIVATION);
  }
  ~ArchScene() { bridge.reset(); }
};

TEST(ShellBridge, FloorConstraintsDetermineAShellLyingOnTheFloor) {
  for (FloorHold hold : {FloorHold::kControlPoints, FloorHold::kLimitPoints}) {
    SCOPED_TRACE(hold == FloorHold::kControlPoints ? "control points" : "limit points");
    ArchScene with_floor(true, hold);
    ShellBridge& bridge = *with_floor.bridge;
    lockstep(with_floor.scene, bridge, 120);
    const ShellStats stats = bridge.stats(with_floor.shell);
    EXPECT_GT(stats.channel.sent, 0u);
    EXPECT_EQ(stats.channel.failed, 0u);
    EXPECT_FALSE(stats.last_error) << stats.last_error->message;
    EXPECT_GT(stats.results_applied, 0u);
    // Both feet are held, the crown gives under the box.
    const DeformationRequest& floor = bridge.floor(with_floor.shell);
    const auto& now = bridge.control_positions(with_floor.shell);
    const auto& rest = with_floor.mesh.positions();
    if (hold == FloorHold::kControlPoints) {
      EXPECT_EQ(floor.vertex_constraints.size(), 10u);
      for (const VertexConstraint& c : floor.vertex_constraints) {
        EXPECT_LT((now[size_t(c.index)] - rest[size_t(c.index)]).norm(), 1e-6);
      }
    } else {
      // One limit point per touching face: the 4 faces along each foot.
      EXPECT_EQ(floor.limit_constraints.size(), 8u);
      const auto evaluator = LimitEvaluator::create(with_floor.mesh).value();
      for (const LimitConstraint& c : floor.limit_constraints) {
        EXPECT_LT((evaluator.evaluate(c.point, now).position - evaluator.evaluate(c.point).position).norm(), 1e-6);
      }
    }
    const size_t crown = size_t(test::grid_index(8, 4, 2));
    EXPECT_LT(now[crown].z() - rest[crown].z(), -1e-5);
    const DeformationRequest* sent = bridge.last_sent_request(with_floor.shell);
    ASSERT_NE(sent, nullptr);
    EXPECT_NEAR(total_force(*sent).z(), -2.0 * kGravity, 0.05 * 2.0 * kGravity);
  }

  // Without the floor nothing holds the arch: the server says the system is undetermined, the
  // bridge keeps going and reports it.
  ArchScene free(false);
  for (int step = 0; step < 60; ++step) {
    free.scene.world.stepSimulation(static_cast<btScalar>(kStep), 1, static_cast<btScalar>(kStep));
    free.bridge->update();
    ASSERT_TRUE(free.bridge->wait_idle(10s).ok());
  }
  const ShellStats free_stats = free.bridge->stats(free.shell);
  EXPECT_TRUE(free.bridge->floor(free.shell).empty());
  EXPECT_GT(free_stats.channel.failed, 0u);
  // No deformation was shown: the shell stays at rest. (With holds the server may store the empty
  // hold state, the rest shape, after refusing the first put; the bridge shows that.)
  for (size_t i = 0; i < free.mesh.positions().size(); ++i) {
    EXPECT_EQ(free.bridge->control_positions(free.shell)[i], free.mesh.positions()[i]);
  }
  ASSERT_TRUE(free_stats.last_error);
  EXPECT_EQ(free_stats.last_error->code, ErrorCode::kUnprocessable) << free_stats.last_error->message;
}

TEST(ShellBridge, RequestsCarryTheSupportsAndTheSpreadContactForces) {
  // A manual session that never answers on its own: what goes out is what is checked.
  Plate plate;
  test::BulletWorld scene;
  ShellBridge bridge(scene.world);
  auto session = std::make_shared<test::ManualSession>(plate.mesh);
  ShellSettings settings = plate.settings();
  settings.response_time = 0.0;
  settings.stabilize = false;
  settings.min_relative_change = 0.0;
  settings.supports.surface_load = Vec3(0.0, 0.0, -1.0);
  settings.background_mesh_update = false;  // a result shows in the update that receives it
  settings.holds.enabled = false;            // one request per frame (the test double has no holds)
  const ShellId shell = bridge.add_shell(session, GeomId{}, plate.mesh, settings).value();
  btRigidBody* sphere = scene.add_sphere(0.05, 1.5, btVector3(0.11f, -0.07f, 0.06f));
  sphere->setActivationState(DISABLE_DEACTIVATION);

  // Let the sphere come to rest on the (never deforming) plate before the bridge looks.
  for (int step = 0; step < 120; ++step) scene.world.stepSimulation(float(kStep), 1, float(kStep));
  EXPECT_TRUE(session->requests().empty());
  bridge.update();
  ASSERT_EQ(session->requests().size(), 1u);
  const DeformationRequest sent = session->requests().front();
  EXPECT_EQ(sent.vertex_constraints.size(), settings.supports.vertex_constraints.size());
  EXPECT_EQ(sent.surface_load, settings.supports.surface_load);

  // The forces are the contacts' local forces spread with the limit weights at their (face, u, v).
  const auto evaluator = LimitEvaluator::create(plate.mesh).value();
  std::vector<Vec3> expected(size_t(plate.mesh.num_vertices()), Vec3::Zero());
  for (const ContactForce& c : bridge.contacts(shell)) {
    const LimitStencil st = evaluator.stencil(c.point);
    for (size_t k = 0; k < st.size(); ++k) expected[size_t(st.indices[k])] += st.position[k] * c.local_force;
  }
  ASSERT_FALSE(sent.forces.empty());
  for (const PointForce& f : sent.forces) {
    EXPECT_LT((f.force - expected[size_t(f.index)]).norm(), 1e-9);
    expected[size_t(f.index)].setZero();
  }
  for (const Vec3& rest : expected) EXPECT_TRUE(rest.isZero(0.0)) << rest.transpose();
  EXPECT_NEAR(total_force(sent).z(), -1.5 * kGravity, 0.01 * 1.5 * kGravity);

  // Unanswered: the next frames wait in one pending slot, each replacing the one before.
  for (int step = 0; step < 50; ++step) {
    scene.world.stepSimulation(float(kStep), 1, float(kStep));
    bridge.update();
    EXPECT_LE(bridge.stats(shell).channel.max_depth, 2u);
  }
  EXPECT_EQ(session->requests().size(), 1u);
  EXPECT_EQ(bridge.stats(shell).channel.replaced + 1, bridge.stats(shell).channel.submitted - 1);
  // Once answered, only the newest goes out.
  session->answer();
  bridge.update();
  EXPECT_EQ(session->requests().size(), 2u);
  EXPECT_EQ(bridge.stats(shell).res_id, 1u);
  EXPECT_EQ(bridge.stats(shell).results_applied, 1u);
}

TEST(ShellBridge, HandlesAndBadSettings) {
  Plate plate;
  test::BulletWorld scene;
  ShellBridge bridge(scene.world);
  auto session = std::make_shared<test::ManualSession>(plate.mesh);
  ShellSettings settings = plate.settings();
  settings.holds.enabled = false;
  const ShellId a = bridge.add_shell(session, GeomId{}, plate.mesh, settings).value();
  const ShellId b = bridge.add_shell(session, GeomId{}, plate.mesh, settings).value();
  EXPECT_EQ(bridge.shells().size(), 2u);
  EXPECT_EQ(scene.world.getNumCollisionObjects(), 2);
  ASSERT_TRUE(bridge.remove_shell(a).ok());
  EXPECT_FALSE(bridge.valid(a));
  EXPECT_TRUE(bridge.valid(b));
  EXPECT_EQ(bridge.remove_shell(a).error().code, ErrorCode::kNotFound);
  EXPECT_THROW(bridge.stats(a), Exception);
  EXPECT_EQ(scene.world.getNumCollisionObjects(), 1);
  // The slot is reused with a new generation: the old handle stays invalid.
  const ShellId c = bridge.add_shell(session, GeomId{}, plate.mesh, settings).value();
  EXPECT_EQ(c.index, a.index);
  EXPECT_NE(c.generation, a.generation);
  EXPECT_FALSE(bridge.valid(a));
  EXPECT_FALSE(bridge.valid(ShellId{}));

  ShellSettings bad = plate.settings();
  bad.mesh.level = 12;
  EXPECT_EQ(bridge.add_shell(session, GeomId{}, plate.mesh, bad).error().code, ErrorCode::kInvalidArgument);
  bad = plate.settings();
  bad.contacts.force_scale = 0.0;
  EXPECT_EQ(bridge.add_shell(session, GeomId{}, plate.mesh, bad).error().code, ErrorCode::kInvalidArgument);
  bad = plate.settings();
  bad.max_request_rate = -1.0;
  EXPECT_EQ(bridge.add_shell(session, GeomId{}, plate.mesh, bad).error().code, ErrorCode::kInvalidArgument);
  bad = plate.settings();
  bad.floor.enabled = true;
  bad.floor.normal = Vec3::Zero();
  EXPECT_EQ(bridge.add_shell(session, GeomId{}, plate.mesh, bad).error().code, ErrorCode::kInvalidArgument);
  EXPECT_EQ(bridge.add_shell(nullptr, GeomId{}, plate.mesh, plate.settings()).error().code,
            ErrorCode::kInvalidArgument);
  // Hold ids: [A-Za-z0-9._-], room for ".contacts" within 64 characters; a lease in (0, 600 s].
  for (const std::string& name : std::vector<std::string>{"a b", "slash/", std::string(56, 'x')}) {
    bad = plate.settings();
    bad.holds.name = name;
    EXPECT_EQ(bridge.add_shell(session, GeomId{}, plate.mesh, bad).error().code, ErrorCode::kInvalidArgument) << name;
  }
  bad = plate.settings();
  bad.holds.ttl = 0ms;
  EXPECT_EQ(bridge.add_shell(session, GeomId{}, plate.mesh, bad).error().code, ErrorCode::kInvalidArgument);
  // With holds the session must have them: the test double refuses, and add_shell says so.
  EXPECT_FALSE(bridge.add_shell(session, GeomId{}, plate.mesh, plate.settings()).ok());
  EXPECT_EQ(bridge.shells().size(), 2u);
}

}  // namespace
}  // namespace softshell::bullet
