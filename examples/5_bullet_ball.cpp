// Example 5: a Bullet ball resting on a shell. A 1 kg ball drops onto a plastic plate held at its
// edges; the Bullet bridge turns the contact impulses into forces on the shell, sends them to the
// server without blocking, and moves the plate's collision mesh to each result, so the ball
// settles in the dent it makes. At rest the plate carries the ball's weight, and the dent is as
// deep as plate theory says.
#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <memory>
#include <thread>
#include <vector>

#include <btBulletDynamicsCommon.h>

#include "softshell/bullet/shell_bridge.h"
#include "softshell/embedded_session.h"

using namespace softshell;

int main() try {
  // The usual Bullet world, z up.
  btDefaultCollisionConfiguration configuration;
  btCollisionDispatcher dispatcher(&configuration);
  btDbvtBroadphase broadphase;
  btSequentialImpulseConstraintSolver solver;
  btDiscreteDynamicsWorld world(&dispatcher, &broadphase, &solver, &configuration);
  world.setGravity(btVector3(0, 0, -9.81f));

  // The shell: a 1 m x 1 m plate, 5 mm polycarbonate, 12 x 12 faces, every boundary control point
  // fixed, centred at the origin of the world.
  const int n = 12;
  std::vector<Vec3> points;
  for (int j = 0; j <= n; ++j)
    for (int i = 0; i <= n; ++i) points.emplace_back(double(i) / n, double(j) / n, 0.0);
  std::vector<std::vector<int32_t>> quads;
  for (int j = 0; j < n; ++j)
    for (int i = 0; i < n; ++i)
      quads.push_back({j * (n + 1) + i, j * (n + 1) + i + 1, (j + 1) * (n + 1) + i + 1, (j + 1) * (n + 1) + i});
  const ControlMesh plate(points, quads);
  bullet::ShellSettings settings;
  settings.transform.setOrigin(btVector3(-0.5f, -0.5f, 0.0f));
  for (int k = 0; k < plate.num_vertices(); ++k) {
    const int i = k % (n + 1), j = k / (n + 1);
    if (i == 0 || j == 0 || i == n || j == n) settings.supports.vertex_constraints.push_back({k, kAxisAll, Vec3::Zero()});
  }
  bullet::ShellBridge bridge(world);
  const bullet::ShellId shell =
      bridge.add_shell(std::make_shared<EmbeddedSession>(), plate, material_preset("polycarbonate", 0.005).value(), settings)
          .value();

  // The ball: 1 kg, 5 cm radius, 3 cm above the plate.
  const double mass = 1.0;
  btSphereShape sphere(0.05f);
  btVector3 inertia;
  sphere.calculateLocalInertia(btScalar(mass), inertia);
  btDefaultMotionState motion(btTransform(btQuaternion::getIdentity(), btVector3(0, 0, 0.08f)));
  btRigidBody ball(btRigidBody::btRigidBodyConstructionInfo(btScalar(mass), &motion, &sphere, inertia));
  ball.setDamping(0.2f, 0.6f);
  world.addRigidBody(&ball);

  // The game's physics loop at 60 Hz: step, then let the bridge read the contacts, send their
  // forces and apply the results that arrived. update() never blocks.
  auto next_frame = std::chrono::steady_clock::now();
  for (int frame = 0; frame < 90; ++frame) {  // 1.5 s
    world.stepSimulation(1.0f / 60.0f, 2, 1.0f / 120.0f);
    bridge.update();
    next_frame += std::chrono::microseconds(16667);
    std::this_thread::sleep_until(next_frame);
  }
  bridge.wait_idle(std::chrono::seconds(10)).value();  // (for a loading screen or a test only)

  const bullet::ShellStats stats = bridge.stats(shell);
  const double carried = -stats.contact_force.z(), weight = mass * 9.81;
  double dent = 0.0;  // the deepest point of the plate as Bullet sees it (its collision mesh)
  for (const Vec3& v : bridge.collision_mesh(shell).tessellation().vertices()) dent = std::max(dent, -v.z());
  // Kirchhoff plate theory for a point load at the centre of a simply supported square plate (the
  // supports of example 1): w = 0.01160 P a^2 / D. The ball is no point and Bullet keeps a margin.
  const double kirchhoff = 0.01160 * weight / material_preset("polycarbonate", 0.005).value().bending_stiffness();
  std::printf("bullet ball: %d contact points carry %.2f N (the ball weighs %.2f N); the dent is %.2f mm deep "
              "(plate theory %.2f mm); %llu results shown\n",
              stats.contacts, carried, weight, 1e3 * dent, 1e3 * kirchhoff,
              static_cast<unsigned long long>(stats.results_applied));
  world.removeRigidBody(&ball);
  return std::abs(carried / weight - 1.0) < 0.05 && std::abs(dent / kirchhoff - 1.0) < 0.15 ? 0 : 1;
} catch (const Exception& e) {
  std::fprintf(stderr, "bullet ball: %s\n", e.what());
  return 1;
}
