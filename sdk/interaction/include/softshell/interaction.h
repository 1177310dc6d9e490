#pragma once
/// \file
/// \brief What a hand does to a shell (paper Section 6.2), as entries of a `DeformationRequest`:
/// grab (a limit constraint that moves a picked limit point, optionally its tangent plane, with the
/// hand), push (a force at a picked point spread over the control points with the limit weights)
/// and floor (every part of the object that touches a plane is held there).
///
/// Displacements are always relative to the rest shape (the geometry as uploaded): the server's
/// linear solve starts from it. Units: the mesh's length unit; forces in N when SI.
///
/// Thread-safety: the free functions only read their arguments and may run concurrently (not while
/// the tessellation they read is being updated); `Grab` is an immutable value.

#include <cstdint>
#include <optional>
#include <vector>

#include <Eigen/Geometry>

#include "softshell/deformation.h"
#include "softshell/limit_evaluator.h"
#include "softshell/result.h"
#include "softshell/tessellation.h"

namespace softshell {

struct Pick;

/// The Lagrange form of a limit constraint, built from the client's own limit stencil (what the
/// server does with `limit_constraints`; useful for the binary wire layout, which has no limit
/// constraints). The first entry constrains the position on the axes in `axes` (1..7; the other
/// axes' equations get zero coefficients and zero values, which the server drops); then one entry
/// per prescribed tangent (all three axes). The weights are the evaluator's: they match the
/// server's when both evaluate with the same options. kInvalidArgument for a bad point, mask or
/// non-finite value.
Result<std::vector<LagrangeConstraint>> to_lagrange(const LimitEvaluator& evaluator, const LimitConstraint& constraint,
                                                    uint32_t axes = kAxisAll);

/// A force at a surface point as forces on control points: f_A = N_A(p) F for every control point
/// A of the point's stencil (the total is F: the weights sum to 1). kInvalidArgument for a bad
/// point or a non-finite force.
Result<std::vector<PointForce>> spread_force(const LimitEvaluator& evaluator, const SurfaceForce& force);

/// A push at a picked point: `magnitude` (N) along the ray direction (`direction` need not be unit).
SurfaceForce push(const Pick& pick, const Vec3& direction, double magnitude);

/// A rigid pose (a hand, a controller).
struct Pose {
  Vec3 position = Vec3::Zero();
  Eigen::Quaterniond orientation = Eigen::Quaterniond::Identity();  ///< need not be normalized; not zero
};

/// Options of a grab.
struct GrabOptions {
  /// The grabbed point is attached rigidly to the hand at its offset from it, so rotating the hand
  /// swings it around (a ray grab from a distance). false: it only follows the hand's translation.
  bool follow_rotation = true;
  /// Also turn the tangent plane at the point with the hand (the constraint then prescribes the
  /// tangents' change too: `du_displacement`, `dv_displacement`).
  bool constrain_tangents = false;
};

/// A grab in progress: the limit point at `point` follows the hand (paper Section 6.2).
///
/// `begin` records where the point and its tangents are when grabbed (on the shape being shown,
/// which may already be deformed) and where the hand is; `constraint(hand)` then gives the limit
/// constraint for the hand's current pose. Send it (with the other constraints, e.g. the floor)
/// every time the hand moves; the deformed limit surface at `point` is then exactly the target.
///
/// A value type (copyable); all members const after `begin`, safe to share between threads.
class Grab {
 public:
  /// `current_positions` (#V): the control points of the shape shown (the rest positions when
  /// nothing is deformed). kInvalidArgument for a bad point, count, non-finite pose or zero
  /// orientation.
  static Result<Grab> begin(const LimitEvaluator& evaluator, const SurfacePoint& point,
                            const std::vector<Vec3>& current_positions, const Pose& hand,
                            const GrabOptions& options = {});

  /// Where the grabbed point belongs for the hand at `hand`.
  Vec3 target(const Pose& hand) const;
  /// The limit constraint moving the point there, displacement relative to the rest shape
  /// (plus the tangents' change if `constrain_tangents`). Non-finite poses give the grab-time
  /// target (never NaN).
  LimitConstraint constraint(const Pose& hand) const;

  const SurfacePoint& point() const { return point_; }
  const Vec3& rest_position() const { return rest_x_; }
  const Vec3& grabbed_position() const { return grab_x_; }
  const GrabOptions& options() const { return options_; }

 private:
  Eigen::Matrix3d rotation_since_grab(const Pose& hand) const;
  SurfacePoint point_;
  Vec3 rest_x_, rest_du_, rest_dv_;  // rest shape
  Vec3 grab_x_, grab_du_, grab_dv_;  // shape shown when grabbed
  Pose hand0_;
  GrabOptions options_;
};

/// A plane: the points x with normal . (x - point) = 0; `normal` (need not be unit) points out of
/// the floor, towards where the object is.
struct Plane {
  Vec3 point = Vec3::Zero();
  Vec3 normal = Vec3::UnitY();
};

/// Which displacement components a floor contact holds.
enum class FloorAxes : uint8_t {
  kAll,     ///< all three (the contact sticks: no sliding); a limit constraint per contact point
  kNormal,  ///< only along the floor normal (sliding allowed). Lagrange constraints act per axis
            ///< (PROTOCOL.md), so the normal must be a coordinate axis (±x, ±y or ±z)
};

struct FloorOptions {
  /// Samples within this distance above the plane (or below it) touch. Length unit; < 0 means
  /// 1e-3 of the object's size (bounding diagonal of the rest control points).
  double tolerance = -1.0;
  FloorAxes axes = FloorAxes::kAll;
  /// Move touching points onto the plane (their normal displacement puts them on it) instead of
  /// holding them where they are.
  bool snap = false;
};

/// The constraints that hold an object on a floor.
///
/// How they are chosen: the limit surface is sampled at the tessellation's vertices (exact limit
/// points of the shape shown); samples within the tolerance touch. Per control face with touching
/// samples, one limit point is constrained: the touching sample nearest to the centroid of that
/// face's touching samples. One point per face keeps the constraint rows independent (a face's
/// limit surface spans at most one patch's control points; many points of one patch would give
/// nearly dependent rows and an ill-conditioned solve), while every touching region is held.
/// Displacements hold each point where it is shown (or snap it onto the plane).
struct FloorContact {
  std::vector<LimitConstraint> limit_constraints;        ///< FloorAxes::kAll
  std::vector<LagrangeConstraint> lagrange_constraints;  ///< FloorAxes::kNormal (one axis each)
  std::vector<SurfacePoint> points;                      ///< the constrained limit points
  int32_t touching_samples = 0;                          ///< tessellation vertices within the tolerance
  /// True if these constraints alone remove all six rigid-body motions (the rank of the rigid
  /// modes at the constrained points is 6). If false, add constraints or the solve reports an
  /// undetermined system: e.g. a single contact point, contacts along one line, or kNormal only.
  bool fixes_rigid_motion = false;

  /// Appends the constraints to a request.
  void add_to(DeformationRequest& request) const;
};

/// Which samples of the shape `tessellation` shows touch `floor`: the indices (ascending) of the
/// tessellation's vertices at most `tolerance` above the plane, or below it. `tolerance` < 0 means
/// 1e-3 of the object's size (the bounding diagonal of its rest control points). The one rule of
/// every floor in softshell (`floor_contact` here, the Bullet bridge's floor constraints).
/// kInvalidArgument for a non-finite plane or tolerance or a zero normal.
Result<std::vector<int32_t>> floor_touching_samples(const Tessellation& tessellation, const Plane& floor,
                                                    double tolerance);

/// The coordinate axis (0, 1, 2) a normal lies along (either sign, to 1e-9 of its length), or -1.
int coordinate_axis(const Vec3& normal);

/// The floor constraints for the shape `tessellation` currently shows (after `update`, the
/// deformed one). kInvalidArgument for a non-finite plane or tolerance, a zero normal, or kNormal
/// with a normal that is not a coordinate axis. No sample touching is not an error (empty result).
Result<FloorContact> floor_contact(const Tessellation& tessellation, const Plane& floor,
                                   const FloorOptions& options = {});

}  // namespace softshell
