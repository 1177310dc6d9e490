#include "softshell/bullet/shell_bridge.h"

#include <cmath>
#include <cstdio>

#include <gtest/gtest.h>

#include "bullet_world.h"
#include "test_meshes.h"
#include "test_sessions.h"

namespace softshell::bullet {
namespace {

using namespace std::chrono_literals;

std::shared_ptr<Session> make_session() { return std::make_shared<test::EngineSession>(); }

constexpr double kGravity = 9.81;
constexpr double kStep = 1.0 / 120.0;

// A 1 m x 1 m plastic plate (E = 2 GPa, t = 5 mm), 12 x 12 faces, centred at the origin in the
// z = 0 plane, with every boundary control point fixed.
struct Plate {
  static constexpr int kN = 12;
  ControlMesh mesh = test::make_grid(kN, kN, 1.0, 1.0);
  Material material{2.0e9, 0.35, 0.005, 1200.0};

  ShellSettings settings() const {
    ShellSettings s;
    s.mesh.level = 2;
    s.max_request_rate = 0.0;  // the tests pace themselves
    s.transform.setOrigin(btVector3(-0.5f, -0.5f, 0.0f));
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

// What a sphere dropped on the plate did, once at rest.
struct DropOutcome {
  int32_t max_contacts = 0;
  Vec3 sent_force = Vec3::Zero();          // total force of the last request sent (N)
  double max_deflection = 0.0;             // largest downward displacement of the limit surface (m)
  Vec3 max_deflection_at = Vec3::Zero();   // where (world frame)
  Vec3 contact_point = Vec3::Zero();       // where the sphere touches (world frame)
  double centre_displacement_z = 0.0;      // limit-surface displacement under the sphere (m)
  ShellStats stats;
};

DropOutcome drop_sphere(double mass, double radius = 0.05) {
  test::BulletWorld scene;
  Plate plate;
  ShellBridge bridge(scene.world);
  auto shell = bridge.add_shell(make_session(), plate.mesh, plate.material, plate.settings());
  EXPECT_TRUE(shell.ok()) << shell.error().message;
  btRigidBody* sphere = scene.add_sphere(radius, mass, btVector3(0.0f, 0.0f, static_cast<btScalar>(radius + 0.03)));
  sphere->setDamping(0.2f, 0.6f);
  sphere->setActivationState(DISABLE_DEACTIVATION);

  DropOutcome out;
  // Lockstep: each step's request is answered before the next step, so every run sees the same
  // sequence of shapes (the asynchronous, real-time behaviour is tested with a slowed server).
  for (int step = 0; step < 360; ++step) {
    scene.world.stepSimulation(static_cast<btScalar>(kStep), 1, static_cast<btScalar>(kStep));
    bridge.update();
    EXPECT_TRUE(bridge.wait_idle(10s).ok());
    out.max_contacts = std::max(out.max_contacts, bridge.stats(*shell).contacts);
    if (getenv("TRACE") && step % 10 == 0) {
      const btVector3 p = sphere->getWorldTransform().getOrigin();
      const btVector3 v = sphere->getLinearVelocity();
      std::printf("%3d pos %8.4f %8.4f %8.4f vel %8.4f %8.4f %8.4f tau %.3f C %.3g contacts %d force %s res %u\n", step, p.x(), p.y(), p.z(), v.x(), v.y(), v.z(), bridge.stats(*shell).time_constant, bridge.stats(*shell).compliance,
                  bridge.stats(*shell).contacts, ::testing::PrintToString(bridge.stats(*shell).contact_force.transpose()).c_str(), bridge.stats(*shell).res_id);
    }
  }
  // Let the last requests land and the sphere settle in the dent, then finish.
  for (int round = 0; round < 3; ++round) {
    EXPECT_TRUE(bridge.wait_idle(10s).ok());
    for (int step = 0; step < 30; ++step) {
      scene.world.stepSimulation(static_cast<btScalar>(kStep), 1, static_cast<btScalar>(kStep));
      bridge.update();
    }
  }
  EXPECT_TRUE(bridge.wait_idle(10s).ok());

  out.stats = bridge.stats(*shell);
  const DeformationRequest* sent = bridge.last_sent_request(*shell);
  EXPECT_NE(sent, nullptr);
  if (sent) out.sent_force = total_force(*sent);
  const auto& contacts = bridge.contacts(*shell);
  EXPECT_FALSE(contacts.empty());
  if (!contacts.empty()) out.contact_point = contacts.front().position;

  // Deflection of the limit surface: tessellation vertices now vs rest.
  const CollisionMesh& mesh = bridge.collision_mesh(*shell);
  const auto& now = mesh.tessellation().vertices();
  const auto rest = Tessellation::create(LimitEvaluator::create(plate.mesh).value(), 2).value();
  const Vec3 offset(-0.5, -0.5, 0.0);
  double best_distance = 1e9;
  for (size_t i = 0; i < now.size(); ++i) {
    const double dz = now[i].z() - rest.vertices()[i].z();
    if (-dz > out.max_deflection) {
      out.max_deflection = -dz;
      out.max_deflection_at = rest.vertices()[i] + offset;
    }
    const double d = (rest.vertices()[i] + offset - out.contact_point).head<2>().norm();
    if (d < best_distance) {
      best_distance = d;
      out.centre_displacement_z = dz;
    }
  }
  return out;
}

TEST(ShellBridge, SphereOnPlateDentsItAndSendsItsWeight) {
  const double mass = 1.0;
  const DropOutcome drop = drop_sphere(mass);
  EXPECT_GT(drop.max_contacts, 0);
  EXPECT_GT(drop.stats.results_applied, 0u);
  EXPECT_FALSE(drop.stats.last_error) << drop.stats.last_error->message;

  // At rest the force sent is the sphere's weight.
  const Vec3 weight(0.0, 0.0, -mass * kGravity);
  EXPECT_LT((drop.sent_force - weight).norm(), 0.05 * weight.norm())
      << "sent " << drop.sent_force.transpose() << ", weight " << weight.transpose();

  // The plate deflects down under the sphere, most near the contact.
  EXPECT_LT(drop.centre_displacement_z, 0.0);
  EXPECT_GT(drop.max_deflection, 1e-4);
  EXPECT_LT((drop.max_deflection_at - drop.contact_point).head<2>().norm(), 0.1)
      << "largest deflection at " << drop.max_deflection_at.transpose() << ", contact at "
      << drop.contact_point.transpose();
  // Order of magnitude of a point-loaded Kirchhoff plate (0.0056 .. 0.0116 P a^2 / D).
  const double D = 2.0e9 * std::pow(0.005, 3) / (12.0 * (1.0 - 0.35 * 0.35));
  EXPECT_GT(drop.max_deflection, 0.3 * 0.0056 * mass * kGravity / D);
  EXPECT_LT(drop.max_deflection, 3.0 * 0.0116 * mass * kGravity / D);
}

TEST(ShellBridge, TwiceTheMassGivesTwiceTheDeflection) {
  const DropOutcome one = drop_sphere(1.0);
  const DropOutcome two = drop_sphere(2.0);
  ASSERT_GT(one.max_deflection, 0.0);
  EXPECT_NEAR(two.max_deflection / one.max_deflection, 2.0, 0.1)
      << one.max_deflection << " vs " << two.max_deflection;
  for (const DropOutcome* d : {&one, &two}) {
    std::printf("sent %s contact %s max at %s centre dz %g stats sent %llu replaced %llu unchanged %llu\n",
                ::testing::PrintToString(d->sent_force.transpose()).c_str(),
                ::testing::PrintToString(d->contact_point.transpose()).c_str(),
                ::testing::PrintToString(d->max_deflection_at.transpose()).c_str(), d->centre_displacement_z,
                (unsigned long long)d->stats.channel.sent, (unsigned long long)d->stats.channel.replaced,
                (unsigned long long)d->stats.unchanged_frames);
  }
}

}  // namespace
}  // namespace softshell::bullet
