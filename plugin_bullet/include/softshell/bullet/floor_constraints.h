#pragma once
/// \file
/// \brief Floor constraints: the parts of a shell that touch the ground plane are held there
/// (paper Section 6.2), so a free object lying on the floor has a determined deformation.

#include <cstdint>
#include <vector>

#include <Eigen/Geometry>

#include "softshell/control_mesh.h"
#include "softshell/deformation.h"
#include "softshell/result.h"
#include "softshell/tessellation.h"

namespace softshell::bullet {

/// How the parts of a shell that touch the floor are held.
enum class FloorHold : uint8_t {
  /// Vertex constraints on the control points that dominate the touching parts (below). Binary
  /// layout; the fixed degrees of freedom stay the same, so the server reuses one factorization.
  kControlPoints,
  /// The sdk's `floor_contact` (interaction.h): one limit point per touching control face held
  /// exactly where it is (limit constraints; JSON-only, a constraint block in every solve).
  kLimitPoints,
};

/// The ground plane and how a shell touching it is held.
struct FloorSettings {
  bool enabled = false;             ///< add floor constraints to the shell's requests
  Vec3 point = Vec3::Zero();        ///< a point of the floor plane, world frame (length unit)
  Vec3 normal = Vec3::UnitY();      ///< floor normal, world frame, pointing up out of the floor (any length > 0)
  /// Surface samples at most this far above the plane (or below it) touch it (length unit);
  /// < 0 means 1e-3 of the shell's size (bounding diagonal of its rest control points). The
  /// rule is the SDK's `floor_touching_samples`, the same for both holds.
  double tolerance = -1.0;
  /// Axes (bits 1 = x, 2 = y, 4 = z of the shell's local frame) held at every touching point.
  /// All three (the default) is a contact that sticks; holding only the axis along the normal
  /// lets the shell slide and usually leaves it undetermined. With kLimitPoints the mask is all
  /// three or the single axis of the floor normal in the shell's frame.
  uint32_t mask = kAxisAll;
  FloorHold hold = FloorHold::kControlPoints;
};

/// The vertex constraints that hold a shell on the floor.
///
/// The limit surface is sampled at the tessellation's vertices (the shape it shows now, in the
/// shell's local frame, placed in the world by `shell_to_world`); the samples that touch are the
/// SDK's `floor_touching_samples` (interaction.h). At every touching sample, the control point with the largest limit weight there (the one that
/// dominates the surface at that point: the vertex itself at a control vertex's limit point) is
/// held with zero displacement on `mask`'s axes. Each control point appears once, in ascending
/// order. Vertex constraints keep the request in the binary layout and the set of fixed degrees
/// of freedom the same from frame to frame, so the server reuses one cached factorization.
///
/// kInvalidArgument for a non-finite plane or tolerance, a zero normal, or a mask outside 1..7.
/// No sample touching is not an error (empty result).
Result<std::vector<VertexConstraint>> floor_constraints(const Tessellation& tessellation,
                                                        const Eigen::Isometry3d& shell_to_world,
                                                        const FloorSettings& settings);

/// The floor's part of a shell's requests, as `settings.hold` says: vertex constraints from
/// `floor_constraints`, or the limit (or, for a normal-only mask, Lagrange) constraints of the
/// sdk's `floor_contact` with the plane taken into the shell's frame. Empty if nothing touches.
/// kInvalidArgument as `floor_constraints`, and for kLimitPoints with a mask that is neither all
/// axes nor the normal's axis.
Result<DeformationRequest> floor_request(const Tessellation& tessellation, const Eigen::Isometry3d& shell_to_world,
                                         const FloorSettings& settings);

}  // namespace softshell::bullet
