#pragma once
// A small Bullet world for the bridge tests and the benchmark: owns the usual five objects and the
// bodies added to it.

#include <memory>
#include <vector>

#include <btBulletDynamicsCommon.h>

namespace softshell::test {

struct BulletWorld {
  btDefaultCollisionConfiguration configuration;
  btCollisionDispatcher dispatcher{&configuration};
  btDbvtBroadphase broadphase;
  btSequentialImpulseConstraintSolver solver;
  btDiscreteDynamicsWorld world{&dispatcher, &broadphase, &solver, &configuration};
  std::vector<std::unique_ptr<btCollisionShape>> shapes;
  std::vector<std::unique_ptr<btDefaultMotionState>> motion_states;
  std::vector<std::unique_ptr<btRigidBody>> bodies;

  explicit BulletWorld(const btVector3& gravity = btVector3(0, 0, -9.81f)) { world.setGravity(gravity); }
  ~BulletWorld() {
    for (auto& body : bodies) world.removeRigidBody(body.get());
  }
  BulletWorld(const BulletWorld&) = delete;
  BulletWorld& operator=(const BulletWorld&) = delete;

  btRigidBody* add_body(std::unique_ptr<btCollisionShape> shape, double mass, const btVector3& position) {
    btVector3 inertia(0, 0, 0);
    if (mass > 0) shape->calculateLocalInertia(static_cast<btScalar>(mass), inertia);
    btTransform start;
    start.setIdentity();
    start.setOrigin(position);
    motion_states.push_back(std::make_unique<btDefaultMotionState>(start));
    btRigidBody::btRigidBodyConstructionInfo info(static_cast<btScalar>(mass), motion_states.back().get(),
                                                  shape.get(), inertia);
    info.m_restitution = 0.0f;
    info.m_friction = 0.5f;
    bodies.push_back(std::make_unique<btRigidBody>(info));
    shapes.push_back(std::move(shape));
    world.addRigidBody(bodies.back().get());
    return bodies.back().get();
  }
  btRigidBody* add_sphere(double radius, double mass, const btVector3& position) {
    return add_body(std::make_unique<btSphereShape>(static_cast<btScalar>(radius)), mass, position);
  }
  btRigidBody* add_box(const btVector3& half_extents, double mass, const btVector3& position) {
    return add_body(std::make_unique<btBoxShape>(half_extents), mass, position);
  }
};

}  // namespace softshell::test
