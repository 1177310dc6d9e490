#include "softshell/bullet/contact_forces.h"

#include <gtest/gtest.h>

#include "bullet_world.h"
#include "softshell/bullet/collision_mesh.h"
#include "test_meshes.h"

namespace softshell::bullet {
namespace {

// A sphere resting on a static (undeformed) plate, read straight from Bullet's manifolds.
struct RestingSphere {
  test::BulletWorld scene;
  std::unique_ptr<CollisionMesh> mesh;
  btCollisionObject plate;
  btRigidBody* sphere = nullptr;

  // `plate_first`: add the plate to the world before the sphere (it may then be either body of
  // the manifold; both sides must work).
  RestingSphere(bool plate_first, const btTransform& placement, const btVector3& gravity, const btVector3& drop_at)
      : scene(gravity) {
    CollisionMeshSettings settings;
    settings.level = 2;
    mesh = CollisionMesh::create(LimitEvaluator::create(test::make_grid(6, 6)).value(), settings).value();
    plate.setCollisionShape(&mesh->shape());
    plate.setWorldTransform(placement);
    if (plate_first) scene.world.addCollisionObject(&plate, 2, ~2);
    sphere = scene.add_sphere(0.05, 2.0, drop_at);
    if (!plate_first) scene.world.addCollisionObject(&plate, 2, ~2);
    for (int i = 0; i < 240; ++i) scene.world.stepSimulation(1.0f / 120.0f, 1, 1.0f / 120.0f);
  }
  ~RestingSphere() { scene.world.removeCollisionObject(&plate); }

  std::vector<ContactForce> read(const ContactSettings& settings = {}) {
    std::vector<ContactForce> out;
    gather_contact_forces(scene.dispatcher, plate, *mesh, scene.world.getSolverInfo().m_timeStep, settings, out);
    return out;
  }
};

TEST(ContactForces, WeightOfARestingSphereAtItsSurfacePoint) {
  for (bool plate_first : {true, false}) {
    btTransform placement;
    placement.setIdentity();
    placement.setOrigin(btVector3(-0.5f, -0.5f, 0.0f));
    RestingSphere s(plate_first, placement, btVector3(0, 0, -9.81f), btVector3(0.13f, -0.07f, 0.1f));
    const auto contacts = s.read();
    ASSERT_FALSE(contacts.empty());
    Vec3 total = Vec3::Zero();
    for (const ContactForce& c : contacts) {
      total += c.force;
      EXPECT_EQ(c.other, s.sphere);
      EXPECT_GT(c.normal.z(), 0.99);                    // from the plate toward the sphere
      EXPECT_LT((c.local_force - c.force).norm(), 1e-6);  // a translation does not turn forces
      // The contact lies under the sphere (which may have rolled a little), and its surface point
      // is where it is on the plate.
      const btVector3 centre = s.sphere->getWorldTransform().getOrigin();
      EXPECT_NEAR(c.position.x(), centre.x(), 1e-3);
      EXPECT_NEAR(c.position.y(), centre.y(), 1e-3);
      EXPECT_NEAR(c.position.z(), 0.0, 1e-3);
      const auto& quad = s.mesh->tessellation().quads()[size_t(c.triangle / 2)];
      EXPECT_EQ(c.point.face, quad.root_face);
      // Grid face (i, j) covers local [i/6, (i+1)/6] x [j/6, (j+1)/6]; local = world + 0.5.
      const double lx = (c.position.x() + 0.5) * 6.0, ly = (c.position.y() + 0.5) * 6.0;
      EXPECT_EQ(c.point.face, int32_t(ly) * 6 + int32_t(lx));
      EXPECT_NEAR(c.point.u, lx - std::floor(lx), 1e-5);
      EXPECT_NEAR(c.point.v, ly - std::floor(ly), 1e-5);
    }
    EXPECT_NEAR(total.z(), -2.0 * 9.81, 0.01 * 2.0 * 9.81) << "plate first: " << plate_first;
    EXPECT_LT(total.head<2>().norm(), 0.01 * 2.0 * 9.81);

    // Scaling, thresholds.
    ContactSettings scaled;
    scaled.force_scale = 3.0;
    const auto tripled = s.read(scaled);
    ASSERT_EQ(tripled.size(), contacts.size());
    EXPECT_LT((tripled[0].force - 3.0 * contacts[0].force).norm(), 1e-9);
    ContactSettings strict;
    strict.min_force = 1000.0;
    EXPECT_TRUE(s.read(strict).empty());
    strict = {};
    strict.contact_threshold = -1.0;  // only points penetrating by more than 1 m
    EXPECT_TRUE(s.read(strict).empty());
  }
}

TEST(ContactForces, RotatedShellGetsForcesInItsOwnFrame) {
  // The plate's local z points along the world's y (a y-up world, the plate lying on its back).
  btTransform placement;
  placement.setIdentity();
  placement.setRotation(btQuaternion(btVector3(1, 0, 0), -SIMD_HALF_PI));
  placement.setOrigin(btVector3(-0.5f, 0.0f, 0.5f));
  RestingSphere s(true, placement, btVector3(0, -9.81f, 0), btVector3(0.1f, 0.1f, -0.1f));
  const auto contacts = s.read();
  ASSERT_FALSE(contacts.empty());
  Vec3 world = Vec3::Zero(), local = Vec3::Zero();
  for (const ContactForce& c : contacts) {
    world += c.force;
    local += c.local_force;
  }
  EXPECT_NEAR(world.y(), -2.0 * 9.81, 0.2);
  EXPECT_NEAR(local.z(), -2.0 * 9.81, 0.2);
  EXPECT_LT(local.head<2>().norm(), 0.2);
}

}  // namespace
}  // namespace softshell::bullet
