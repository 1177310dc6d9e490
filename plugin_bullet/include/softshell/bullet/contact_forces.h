#pragma once
/// \file
/// \brief `ContactForce`: what a Bullet contact does to a shell, read from the contact manifolds
/// after `stepSimulation` (force = applied impulse / time step, at the contact's `(face, u, v)`).

#include <cstdint>
#include <limits>
#include <vector>

#include "softshell/control_mesh.h"
#include "softshell/limit_evaluator.h"

class btCollisionObject;
class btDispatcher;
class btManifoldPoint;

namespace softshell::bullet {

class CollisionMesh;

/// Which manifold points count, and how they turn into forces.
struct ContactSettings {
  /// Manifold points whose distance (negative = penetration) is above this are ignored (length
  /// unit). Bullet applies impulses only at points that touch or are about to, so the default
  /// counts every point that carries an impulse.
  double contact_threshold = std::numeric_limits<double>::infinity();
  /// Include the friction impulses (along the manifold point's lateral friction directions).
  bool friction = true;
  /// Contacts whose force is smaller than this are dropped (N, >= 0).
  double min_force = 0.0;
  /// Multiplies every contact force (dimensionless, > 0): 1 is physical; larger exaggerates dents.
  double force_scale = 1.0;
};

/// One contact of a shell in the last Bullet step.
struct ContactForce {
  int32_t triangle = -1;          ///< triangle of the shell's collision mesh (Bullet's triangle index)
  SurfacePoint point;             ///< where it acts on the limit surface (through the quadtree path)
  Vec3 position = Vec3::Zero();   ///< contact point on the shell, world frame (length unit)
  Vec3 normal = Vec3::Zero();     ///< unit contact normal, world frame, from the shell toward the other object
  Vec3 force = Vec3::Zero();      ///< force on the shell, world frame (N, times `force_scale`)
  Vec3 local_force = Vec3::Zero();  ///< the same force in the shell's local frame (its control points' frame)
  const btCollisionObject* other = nullptr;  ///< the object touching the shell (not owned)
};

/// Turns one manifold point between a shell and another object into a contact force.
///
/// `shell_is_body0` tells on which side of the manifold the shell is. The impulse Bullet applied
/// to body 0 is `+normalWorldOnB * appliedImpulse` (+ lateral directions times the lateral
/// impulses), to body 1 the opposite; divided by `time_step` (s) it is the force of that step
/// (N). The triangle index comes from the manifold point (`m_index0` / `m_index1`, which Bullet's
/// convex-concave algorithm fills for triangle meshes); the barycentric position from the contact
/// position on the shell. Returns false (and leaves `out` unspecified) if the point is ignored:
/// distance above the threshold, no or a bad triangle index, zero force.
bool contact_force(const btManifoldPoint& point, bool shell_is_body0, const btCollisionObject& shell_object,
                   const CollisionMesh& mesh, double time_step, const ContactSettings& settings, ContactForce& out);

/// Appends the contacts of `shell_object` (a collision object whose shape is `mesh.shape()`) in
/// every manifold of `dispatcher` (one pass over the manifolds). `time_step` is the step that
/// produced the impulses (Bullet's fixed internal step, `world.getSolverInfo().m_timeStep`).
/// Thread-safety: reads Bullet state; call between `stepSimulation` calls.
void gather_contact_forces(btDispatcher& dispatcher, const btCollisionObject& shell_object,
                           const CollisionMesh& mesh, double time_step, const ContactSettings& settings,
                           std::vector<ContactForce>& out);

}  // namespace softshell::bullet
