#include "bullet_phase.h"

#include <chrono>
#include <cmath>
#include <thread>
#include <cstdio>
#include <cstdlib>
#include <tuple>

#include <btBulletDynamicsCommon.h>

#include "softshell/bullet/shell_bridge.h"

namespace softshell::demo {
namespace {

// A box for the picture: 12 triangles with face normals.
BulletPhaseResult::BodyMesh box_mesh(const btTransform& pose, double half) {
  BulletPhaseResult::BodyMesh m;
  static const int kFaces[6][4] = {{0, 1, 3, 2}, {4, 6, 7, 5}, {0, 4, 5, 1}, {2, 3, 7, 6}, {0, 2, 6, 4}, {1, 5, 7, 3}};
  btVector3 corner[8];
  for (int i = 0; i < 8; ++i) {
    const btVector3 local(static_cast<btScalar>((i & 4 ? 1 : -1) * half), static_cast<btScalar>((i & 2 ? 1 : -1) * half),
                          static_cast<btScalar>((i & 1 ? 1 : -1) * half));
    corner[i] = pose * local;
  }
  for (const auto& face : kFaces) {
    const btVector3 n = (corner[face[1]] - corner[face[0]]).cross(corner[face[2]] - corner[face[0]]).normalized();
    const auto base = static_cast<int32_t>(m.vertices.size());
    for (int k = 0; k < 4; ++k) {
      m.vertices.emplace_back(corner[face[k]].x(), corner[face[k]].y(), corner[face[k]].z());
      m.normals.emplace_back(n.x(), n.y(), n.z());
    }
    m.triangles.push_back({base, base + 1, base + 2});
    m.triangles.push_back({base, base + 2, base + 3});
  }
  return m;
}

}  // namespace

BulletPhaseResult run_bullet_phase(const std::shared_ptr<Session>& session, const GeomId& id,
                                   const ControlMesh& mesh, const FloorContact& floor, double floor_y,
                                   const Picker& picker, int level, int steps,
                                   const std::function<void(uint32_t)>& on_result) {
  BulletPhaseResult out;
  btDefaultCollisionConfiguration configuration;
  btCollisionDispatcher dispatcher(&configuration);
  btDbvtBroadphase broadphase;
  btSequentialImpulseConstraintSolver solver;
  btDiscreteDynamicsWorld world(&dispatcher, &broadphase, &solver, &configuration);
  world.setGravity(btVector3(0, -9.81f, 0));

  Vec3 lo, hi;
  mesh.bounding_box(lo, hi);
  const double size = (hi - lo).norm();
  const Vec3 centre = 0.5 * (lo + hi);

  // The shell, held by the demo's floor contacts (so its results match the rest of the session).
  bullet::ShellBridge bridge(world);
  bullet::ShellSettings settings;
  settings.mesh.level = std::max(1, level - 1);
  // The demo steps Bullet faster than real time, so the wall-clock rate limit (made for a game
  // loop at 60 Hz) would let only a few requests through.
  settings.max_request_rate = 0.0;
  floor.add_to(settings.supports);
  const bullet::ShellId shell = bridge.add_shell(session, id, mesh, settings).value();

  // The ground under everything, so bodies that miss the object still land.
  btStaticPlaneShape ground_shape(btVector3(0, 1, 0), static_cast<btScalar>(floor_y));
  btRigidBody ground(btRigidBody::btRigidBodyConstructionInfo(0.0f, nullptr, &ground_shape));
  world.addRigidBody(&ground);

  // Three boxes of different mass, each just above the point where a vertical ray through the
  // object's top hits it (boxes do not roll off curved backs as spheres do).
  struct Body {
    double mass;
    std::unique_ptr<btBoxShape> shape;
    std::unique_ptr<btDefaultMotionState> motion;
    std::unique_ptr<btRigidBody> body;
  };
  std::vector<Body> bodies;
  const double half = 0.03 * size;
  // Spread along the object's longer horizontal axis.
  const Vec3 along = (hi.x() - lo.x() >= hi.z() - lo.z()) ? Vec3::UnitX() : Vec3::UnitZ();
  for (auto [mass, offset] : {std::pair{1.0, -0.12}, std::pair{5.0, 0.0}, std::pair{20.0, 0.12}}) {
    const Vec3 above = Vec3(centre.x(), hi.y() + 0.5 * size, centre.z()) + offset * size * along;
    auto hit = picker.intersect(Ray{above, -Vec3::UnitY()}).value();
    if (!hit) continue;  // nothing below this spot
    const Vec3 start = above - (hit->t - 1.5 * half) * Vec3::UnitY();
    Body b{mass, std::make_unique<btBoxShape>(btVector3(static_cast<btScalar>(half), static_cast<btScalar>(half),
                                                        static_cast<btScalar>(half))),
           nullptr, nullptr};
    btVector3 inertia(0, 0, 0);
    b.shape->calculateLocalInertia(static_cast<btScalar>(mass), inertia);
    btTransform pose;
    pose.setIdentity();
    pose.setOrigin(btVector3(static_cast<btScalar>(start.x()), static_cast<btScalar>(start.y()),
                             static_cast<btScalar>(start.z())));
    b.motion = std::make_unique<btDefaultMotionState>(pose);
    btRigidBody::btRigidBodyConstructionInfo info(static_cast<btScalar>(mass), b.motion.get(), b.shape.get(), inertia);
    info.m_friction = 0.9f;
    b.body = std::make_unique<btRigidBody>(info);
    world.addRigidBody(b.body.get());
    out.masses.push_back(mass);
    bodies.push_back(std::move(b));
  }
  out.bodies = static_cast<int>(bodies.size());

  // The physics loop runs at four times real time (a 60 Hz game would step every 16.7 ms): fast
  // enough for a demo, slow enough that the server answers between frames as it would in a game.
  uint32_t shown = 0;
  const auto loop_start = std::chrono::steady_clock::now();
  for (int step = 0; step < steps; ++step) {
    std::this_thread::sleep_until(loop_start + step * std::chrono::microseconds(4167));
    world.stepSimulation(1.0f / 60.0f, 1, 1.0f / 60.0f);
    const bullet::UpdateReport report = bridge.update();
    out.contacts += report.contacts;
    const uint32_t res_id = bridge.stats(shell).res_id;
    if (res_id != shown) {
      shown = res_id;
      if (on_result) on_result(res_id);
    }
  }
  (void)bridge.wait_idle(std::chrono::seconds(10));
  bridge.update();
  const bullet::ShellStats stats = bridge.stats(shell);
  if (stats.res_id != shown && on_result) on_result(stats.res_id);
  out.requests = static_cast<int>(stats.channel.sent);
  if (std::getenv("SOFTSHELL_DEMO_DEBUG")) {
    const auto count = [](auto v) { return static_cast<unsigned long long>(v); };
    std::fprintf(stderr, "bridge: submitted %llu sent %llu replaced %llu completed %llu failed %llu unchanged %llu tc %g\n",
                 count(stats.channel.submitted), count(stats.channel.sent), count(stats.channel.replaced),
                 count(stats.channel.completed), count(stats.channel.failed), count(stats.unchanged_frames),
                 stats.time_constant);
    if (stats.last_error) std::fprintf(stderr, "bridge error: %s\n", stats.last_error->message.c_str());
  }
  if (stats.res_id != 0) out.positions = bridge.control_positions(shell);

  for (const Body& b : bodies) {
    btTransform t;
    b.motion->getWorldTransform(t);
    out.body_meshes.push_back(box_mesh(t, half));
    world.removeRigidBody(b.body.get());
  }
  world.removeRigidBody(&ground);
  return out;
}

}  // namespace softshell::demo
