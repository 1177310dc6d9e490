// The bridge as one participant of an object's hold state (PROTOCOL.md version 2): its floor and
// its contacts are holds next to other clients' holds, against the real in-process server (two
// EmbeddedSessions on one service play two clients).
#include <chrono>
#include <thread>

#include <gtest/gtest.h>

#include "bullet_world.h"
#include "softshell/bullet/shell_bridge.h"
#include "softshell/embedded_session.h"
#include "softshell/remote_session.h"
#include "test_meshes.h"

namespace softshell::bullet {
namespace {

using namespace std::chrono_literals;

constexpr double kStep = 1.0 / 120.0;
constexpr int kN = 12;

// Two clients of one server: the bridge's and another's.
struct TwoClients {
  std::shared_ptr<EmbeddedSession> bridge_session = std::make_shared<EmbeddedSession>();
  std::shared_ptr<EmbeddedSession> other = std::make_shared<EmbeddedSession>(bridge_session->service());
};

// A 1 m plastic plate in z = 0 over [0, 1]^2 (local = world), every boundary control point fixed.
ControlMesh plate_mesh() { return test::make_grid(kN, kN, 1.0, 1.0); }
const Material kPlastic{2.0e9, 0.35, 0.005, 1200.0};
size_t centre() { return size_t(test::grid_index(kN, kN / 2, kN / 2)); }

ShellSettings plate_settings(const std::string& name) {
  ShellSettings s;
  s.mesh.level = 2;
  s.max_request_rate = 0.0;
  s.holds.name = name;
  for (int j = 0; j <= kN; ++j) {
    for (int i = 0; i <= kN; ++i) {
      if (i == 0 || j == 0 || i == kN || j == kN) {
        s.supports.vertex_constraints.push_back({test::grid_index(kN, i, j), kAxisAll, Vec3::Zero()});
      }
    }
  }
  return s;
}

// Another client's hand: a force on a control point near the centre (N, world = local frame).
DeformationRequest hand(const Vec3& force) {
  DeformationRequest r;
  r.forces.push_back({int32_t(test::grid_index(kN, kN / 2 - 2, kN / 2)), force});
  return r;
}

std::vector<std::string> hold_ids(Session& session, const GeomId& id) {
  std::vector<std::string> out;
  const HoldList list = session.holds(id).value();
  for (const HoldInfo& h : list.holds) out.push_back(h.hold_id);
  return out;
}

uint64_t version_of(const HoldVersions& versions, const std::string& hold_id) {
  for (const auto& [id, version] : versions) {
    if (id == hold_id) return version;
  }
  return 0;
}

// Updates the bridge (without stepping the world) until it shows result `res_id` or a newer one.
bool shows(ShellBridge& bridge, ShellId shell, uint32_t res_id) {
  for (int i = 0; i < 2000; ++i) {
    bridge.update();
    if (bridge.stats(shell).res_id >= res_id) return true;
    std::this_thread::sleep_for(1ms);
  }
  return false;
}

TEST(ShellBridgeHolds, TheFloorAndTheContactsAreHoldsWhileItRunsAndAreReleasedAfter) {
  TwoClients clients;
  const GeomId id = clients.other->upload(plate_mesh(), kPlastic).value().id;
  test::BulletWorld scene;
  auto bridge = std::make_unique<ShellBridge>(scene.world);
  const ShellId shell = bridge->add_shell(clients.bridge_session, id, plate_mesh(), plate_settings("plate")).value();
  EXPECT_EQ(bridge->floor_hold_id(shell), "plate.floor");
  EXPECT_EQ(bridge->contacts_hold_id(shell), "plate.contacts");
  // The floor hold is there as soon as add_shell returns, with the supports as its contents.
  EXPECT_EQ(hold_ids(*clients.other, id), std::vector<std::string>{"plate.floor"});
  const HoldDetail floor = clients.other->hold(id, "plate.floor").value();
  EXPECT_EQ(floor.request.vertex_constraints.size(), plate_settings("").supports.vertex_constraints.size());

  btRigidBody* sphere = scene.add_sphere(0.05, 1.0, btVector3(0.5f, 0.5f, 0.08f));
  sphere->setActivationState(DISABLE_DEACTIVATION);
  for (int step = 0; step < 240; ++step) {
    scene.world.stepSimulation(float(kStep), 1, float(kStep));
    bridge->update();
    ASSERT_TRUE(bridge->wait_idle(10s).ok());
  }
  const ShellStats stats = bridge->stats(shell);
  EXPECT_FALSE(stats.last_error) << stats.last_error->message;
  EXPECT_EQ(hold_ids(*clients.other, id), (std::vector<std::string>{"plate.contacts", "plate.floor"}));
  // The contacts hold carries the contact forces only (the sphere's weight at rest), and the
  // result shown includes both holds' newest versions.
  const HoldDetail contacts = clients.other->hold(id, "plate.contacts").value();
  EXPECT_TRUE(contacts.request.vertex_constraints.empty());
  Vec3 total = Vec3::Zero();
  for (const PointForce& f : contacts.request.forces) total += f.force;
  EXPECT_NEAR(total.z(), -9.81, 0.05 * 9.81);
  EXPECT_GT(contacts.info.version, 1u);  // each change of the forces is a new version
  EXPECT_EQ(version_of(stats.shown_holds, "plate.contacts"), contacts.info.version);
  EXPECT_EQ(version_of(stats.shown_holds, "plate.floor"), floor.info.version);
  EXPECT_LT(bridge->control_positions(shell)[centre()].z(), -1e-4);  // dented under the sphere

  // Destroyed: both holds are gone and the object is back at rest.
  scene.world.removeRigidBody(sphere);
  bridge.reset();
  EXPECT_TRUE(hold_ids(*clients.other, id).empty());
  const HoldList after = clients.other->holds(id).value();
  const DeformationResult rest = clients.other->result(id, after.res_id).value();
  for (const Vec3& p : rest.positions) EXPECT_LT(std::abs(p.z()), 1e-12);
  scene.world.addRigidBody(sphere);  // BulletWorld removes it again
}

TEST(ShellBridgeHolds, AnotherClientsHoldMovesTheCollisionMeshAndActsWithTheBodies) {
  TwoClients clients;
  const GeomId id = clients.other->upload(plate_mesh(), kPlastic).value().id;
  test::BulletWorld scene;
  ShellBridge bridge(scene.world);
  const ShellSettings settings = plate_settings("plate");
  const ShellId shell = bridge.add_shell(clients.bridge_session, id, plate_mesh(), settings).value();

  // Another client's hand lifts the plate: the bridge's collision mesh follows (from the events,
  // with no body on the plate and no put of its own), and a ray through Bullet hits the lifted surface.
  const HeldResult lifted = clients.other->put_hold(id, "hand", hand(Vec3(0.0, 0.0, 20.0))).value();
  ASSERT_TRUE(shows(bridge, shell, lifted.result.res_id));
  EXPECT_EQ(bridge.stats(shell).channel.sent, 0u);
  EXPECT_GE(bridge.stats(shell).results_from_events, 1u);
  EXPECT_EQ(version_of(bridge.stats(shell).shown_holds, "hand"), 1u);
  for (size_t i = 0; i < lifted.result.positions.size(); ++i) {
    EXPECT_LT((bridge.control_positions(shell)[i] - lifted.result.positions[i]).norm(), 1e-12);
  }
  const double lift = lifted.result.positions[centre()].z();
  ASSERT_GT(lift, 1e-4);
  const btVector3 from(0.5f, 0.5f, 1.0f), to(0.5f, 0.5f, -1.0f);
  btCollisionWorld::ClosestRayResultCallback hit(from, to);
  scene.world.rayTest(from, to, hit);
  ASSERT_TRUE(hit.hasHit());
  EXPECT_GT(hit.m_hitPointWorld.z(), 0.5 * lift);

  // A sphere lands on the lifted plate and rests there: the hold state is the hand, the sphere's
  // contact forces and the supports solved together, the same as one request of all three.
  btRigidBody* sphere = scene.add_sphere(0.05, 1.0, btVector3(0.6f, 0.5f, float(lift) + 0.08f));
  sphere->setActivationState(DISABLE_DEACTIVATION);
  for (int step = 0; step < 240; ++step) {
    scene.world.stepSimulation(float(kStep), 1, float(kStep));
    bridge.update();
    ASSERT_TRUE(bridge.wait_idle(10s).ok());
  }
  const ShellStats stats = bridge.stats(shell);
  EXPECT_FALSE(stats.last_error) << stats.last_error->message;
  const uint64_t contacts_version = clients.other->hold(id, "plate.contacts").value().info.version;
  EXPECT_EQ(version_of(stats.shown_holds, "plate.contacts"), contacts_version);
  EXPECT_EQ(version_of(stats.shown_holds, "hand"), 1u);
  DeformationRequest all = settings.supports;
  all.forces = hand(Vec3(0.0, 0.0, 20.0)).forces;
  const DeformationRequest* sent = bridge.last_sent_request(shell);
  ASSERT_NE(sent, nullptr);
  all.forces.insert(all.forces.end(), sent->forces.begin(), sent->forces.end());
  const DeformationResult alone = clients.other->deform(id, all).value();
  double largest = 0.0;
  for (const Vec3& p : alone.positions) largest = std::max(largest, std::abs(p.z()));
  for (size_t i = 0; i < alone.positions.size(); ++i) {
    EXPECT_LT((bridge.control_positions(shell)[i] - alone.positions[i]).norm(), 1e-9 * largest) << i;
  }

  // The hand lets go: the plate comes down under the sphere alone.
  const HeldResult released = clients.other->release_hold(id, "hand").value();
  ASSERT_TRUE(shows(bridge, shell, released.result.res_id));
  EXPECT_EQ(version_of(bridge.stats(shell).shown_holds, "hand"), 0u);
  EXPECT_LT(bridge.control_positions(shell)[centre()].z(), 0.0);
  scene.world.removeRigidBody(sphere);
  scene.world.addRigidBody(sphere);
}

// ShellSettings::model = kNonlinear: the bridge's floor hold asks for the nonlinear model, so the
// object's hold state is nonlinear, whoever else acts on it. Another client's hand pushing the
// plate up by several thicknesses: the collision mesh shows the nonlinear answer (the same as the
// supports and the hand solved alone with the nonlinear model), which deflects less than the
// linear one (the clamped plate carries a large deflection partly as a membrane).
TEST(ShellBridgeHolds, NonlinearModelOptionMakesTheHoldStateNonlinear) {
  TwoClients clients;
  const GeomId id = clients.other->upload(plate_mesh(), kPlastic).value().id;
  test::BulletWorld scene;
  ShellBridge bridge(scene.world);
  ShellSettings settings = plate_settings("plate");
  settings.model = DeformationModel::kNonlinear;
  const ShellId shell = bridge.add_shell(clients.bridge_session, id, plate_mesh(), settings).value();
  EXPECT_EQ(clients.other->hold(id, "plate.floor").value().request.model, DeformationModel::kNonlinear);

  const Vec3 push(0.0, 0.0, 200.0);  // N; the linear model lifts the plate by ~9 thicknesses
  const HeldResult lifted = clients.other->put_hold(id, "hand", hand(push)).value();
  EXPECT_EQ(lifted.result.model, DeformationModel::kNonlinear);
  EXPECT_LT(lifted.result.residual, 1e-8);
  ASSERT_TRUE(shows(bridge, shell, lifted.result.res_id));
  for (size_t i = 0; i < lifted.result.positions.size(); ++i) {
    EXPECT_LT((bridge.control_positions(shell)[i] - lifted.result.positions[i]).norm(), 1e-12);
  }
  DeformationRequest all = settings.supports;
  all.forces = hand(push).forces;
  const DeformationResult linear = clients.other->deform(id, all).value();
  all.model = DeformationModel::kNonlinear;
  const DeformationResult alone = clients.other->deform(id, all).value();
  const size_t at = size_t(test::grid_index(kN, kN / 2 - 2, kN / 2));
  const double w_linear = linear.positions[at].z(), w_nonlinear = lifted.result.positions[at].z();
  EXPECT_GT(w_linear, 3.0 * kPlastic.thickness);
  EXPECT_LT(w_nonlinear, 0.8 * w_linear);
  EXPECT_GT(w_nonlinear, 0.1 * w_linear);
  for (size_t i = 0; i < alone.positions.size(); ++i) {
    EXPECT_LT((lifted.result.positions[i] - alone.positions[i]).norm(), 1e-6 * w_nonlinear) << i;
  }
}

TEST(ShellBridgeHolds, TwoBridgesOnOneObjectPickTheirOwnHoldIds) {
  TwoClients clients;
  const GeomId id = clients.other->upload(plate_mesh(), kPlastic).value().id;
  test::BulletWorld a_scene, b_scene;
  ShellBridge a(a_scene.world), b(b_scene.world);
  ShellSettings settings = plate_settings("");  // default names: random
  const ShellId sa = a.add_shell(clients.bridge_session, id, plate_mesh(), settings).value();
  const ShellId sb = b.add_shell(clients.other, id, plate_mesh(), settings).value();
  EXPECT_NE(a.floor_hold_id(sa), b.floor_hold_id(sb));
  EXPECT_NE(a.contacts_hold_id(sa), b.contacts_hold_id(sb));
  EXPECT_EQ(hold_ids(*clients.other, id).size(), 2u);
}

// Over HTTP: the floor and contacts holds as PUTs, the collision mesh from the event stream.
TEST(ShellBridgeHolds, WorksThroughARemoteSession) {
  auto server = std::make_shared<EmbeddedSession>();
  const int port = server->listen("127.0.0.1", 0).value();
  std::shared_ptr<Session> remote = RemoteSession::connect("http://127.0.0.1:" + std::to_string(port)).value();
  const GeomId id = remote->upload(plate_mesh(), kPlastic).value().id;
  test::BulletWorld scene;
  auto bridge = std::make_unique<ShellBridge>(scene.world);
  const ShellId shell = bridge->add_shell(remote, id, plate_mesh(), plate_settings("remote")).value();
  btRigidBody* sphere = scene.add_sphere(0.05, 1.0, btVector3(0.5f, 0.5f, 0.08f));
  sphere->setActivationState(DISABLE_DEACTIVATION);
  for (int step = 0; step < 240; ++step) {
    scene.world.stepSimulation(float(kStep), 1, float(kStep));
    bridge->update();
    ASSERT_TRUE(bridge->wait_idle(10s).ok());
  }
  const ShellStats stats = bridge->stats(shell);
  EXPECT_FALSE(stats.last_error) << stats.last_error->message;
  EXPECT_EQ(hold_ids(*server, id), (std::vector<std::string>{"remote.contacts", "remote.floor"}));
  EXPECT_LT(bridge->control_positions(shell)[centre()].z(), -1e-4);
  // A hand of another client: the remote bridge sees it through the event stream.
  const HeldResult pushed = server->put_hold(id, "hand", hand(Vec3(0.0, 0.0, -5.0))).value();
  ASSERT_TRUE(shows(*bridge, shell, pushed.result.res_id));
  EXPECT_EQ(version_of(bridge->stats(shell).shown_holds, "hand"), 1u);
  scene.world.removeRigidBody(sphere);
  bridge.reset();
  EXPECT_EQ(hold_ids(*server, id), std::vector<std::string>{"hand"});
  scene.world.addRigidBody(sphere);
}

}  // namespace
}  // namespace softshell::bullet
