#include "softshell/bullet/contact_forces.h"

#include <cmath>

#include <BulletCollision/BroadphaseCollision/btDispatcher.h>
#include <BulletCollision/CollisionDispatch/btCollisionObject.h>
#include <BulletCollision/NarrowPhaseCollision/btManifoldPoint.h>
#include <BulletCollision/NarrowPhaseCollision/btPersistentManifold.h>

#include "softshell/bullet/collision_mesh.h"

namespace softshell::bullet {

namespace {

Vec3 to_vec(const btVector3& v) { return Vec3(v.x(), v.y(), v.z()); }

}  // namespace

bool contact_force(const btManifoldPoint& point, bool shell_is_body0, const btCollisionObject& shell_object,
                   const CollisionMesh& mesh, double time_step, const ContactSettings& settings, ContactForce& out) {
  if (!(time_step > 0.0)) return false;
  if (static_cast<double>(point.getDistance()) > settings.contact_threshold) return false;
  const int part = shell_is_body0 ? point.m_partId0 : point.m_partId1;
  const int triangle = shell_is_body0 ? point.m_index0 : point.m_index1;
  if (part > 0 || triangle < 0 || triangle >= mesh.num_triangles()) return false;

  // Impulse on body 0 is +n J (+ lateral), on body 1 the opposite (btSequentialImpulseConstraintSolver).
  Vec3 impulse = to_vec(point.m_normalWorldOnB) * static_cast<double>(point.m_appliedImpulse);
  if (settings.friction) {
    impulse += to_vec(point.m_lateralFrictionDir1) * static_cast<double>(point.m_appliedImpulseLateral1);
    impulse += to_vec(point.m_lateralFrictionDir2) * static_cast<double>(point.m_appliedImpulseLateral2);
  }
  if (!shell_is_body0) impulse = -impulse;
  const Vec3 force = impulse * (settings.force_scale / time_step);
  const double magnitude = force.norm();
  if (!(magnitude > 0.0) || magnitude < settings.min_force || !std::isfinite(magnitude)) return false;

  // Where on the shell: world -> shell-local frame -> barycentric -> (face, u, v).
  const btVector3& on_shell = shell_is_body0 ? point.m_positionWorldOnA : point.m_positionWorldOnB;
  const btTransform& transform = shell_object.getWorldTransform();
  const Vec3 local_point = to_vec(transform.invXform(on_shell));
  const btMatrix3x3& basis = transform.getBasis();

  out.triangle = triangle;
  out.point = mesh.surface_point(triangle, local_point);
  out.position = to_vec(on_shell);
  out.normal = shell_is_body0 ? Vec3(-to_vec(point.m_normalWorldOnB)) : to_vec(point.m_normalWorldOnB);
  out.force = force;
  // R^T F: the force in the frame of the control points.
  Eigen::Matrix3d rotation;
  for (int r = 0; r < 3; ++r) rotation.row(r) = to_vec(basis.getRow(r)).transpose();
  out.local_force = rotation.transpose() * force;
  return true;
}

void gather_contact_forces(btDispatcher& dispatcher, const btCollisionObject& shell_object, const CollisionMesh& mesh,
                           double time_step, const ContactSettings& settings, std::vector<ContactForce>& out) {
  const int manifolds = dispatcher.getNumManifolds();
  ContactForce contact;
  for (int m = 0; m < manifolds; ++m) {
    const btPersistentManifold* manifold = dispatcher.getManifoldByIndexInternal(m);
    const bool body0 = manifold->getBody0() == &shell_object;
    if (!body0 && manifold->getBody1() != &shell_object) continue;
    contact.other = body0 ? manifold->getBody1() : manifold->getBody0();
    for (int p = 0; p < manifold->getNumContacts(); ++p) {
      if (contact_force(manifold->getContactPoint(p), body0, shell_object, mesh, time_step, settings, contact)) {
        out.push_back(contact);
      }
    }
  }
}

}  // namespace softshell::bullet
