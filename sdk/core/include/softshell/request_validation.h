#pragma once
/// \file
/// \brief The one validator of deformation requests, at the boundary: the service calls it once
/// per request and the C ABI per added element, so every entry point rejects the same input with
/// the same message. Code behind the boundary (the engine) asserts what it established.

#include <cstdint>
#include <string>

#include "softshell/deformation.h"
#include "softshell/limit_evaluator.h"
#include "softshell/result.h"

namespace softshell {

/// What a request is checked against. Parts left unknown are not checked (the C ABI checks each
/// element when it is added, before the geometry is known).
struct RequestContext {
  static constexpr int32_t kUnknown = -1;
  int32_t num_control_points = kUnknown;     ///< control point indices must be below this
  const LimitEvaluator* evaluator = nullptr;  ///< surface points must lie on its limit surface
};

/// How much one request may ask of a geometry with `num_control_points` control points. Each
/// Lagrange or limit constraint is three equations solved densely beside the cached factor (its
/// cost grows with their number squared, and cubed past a few hundred), so their number is
/// bounded; pinning control points (vertex constraints) costs nothing and is not bounded
/// beyond the DOFs. A request over a limit is refused (kUnprocessable) with a message that says
/// what to do instead.
struct RequestLimits {
  static constexpr size_t kMaxSurfaceConstraints = 256;  ///< Lagrange + limit constraints, at most
  static constexpr size_t kMaxSurfaceForces = 4096;
  /// Vertex constraints and forces cost little each; their counts are bounded so that what a
  /// stored request takes and what `.../request` serves back stay bounded.
  static constexpr size_t kMinElementLimit = 65536;
  size_t surface_constraints;  ///< min(kMaxSurfaceConstraints, control points)
  size_t vertex_constraints;   ///< max(kMinElementLimit, 3 x control points)
  size_t forces;               ///< max(kMinElementLimit, 4 x control points) (repeated indices add up)
  size_t lagrange_terms;       ///< indices of one Lagrange constraint: the control points
  static RequestLimits for_control_points(int32_t num_control_points);
};

/// Ok, or kInvalidArgument naming the first bad element ("vertex constraint 3 has mask 0; ..."):
/// a control point index out of range, a mask outside 1..7, Lagrange indices and coefficients of
/// different counts, a non-finite number, a surface point outside [0, 1]² or not on the surface
/// (face or sub-face out of range, a ghost face). With the control points known, also the
/// counts of `RequestLimits` (kUnprocessable).
Result<void> validate_request(const DeformationRequest& request, const RequestContext& context);

/// The same checks for one element; `position` is its index in the request (for the message).
Result<void> validate(const VertexConstraint& c, size_t position, const RequestContext& context);
Result<void> validate(const LagrangeConstraint& c, size_t position, const RequestContext& context);
Result<void> validate(const PointForce& f, size_t position, const RequestContext& context);
Result<void> validate(const LimitConstraint& c, size_t position, const RequestContext& context);
Result<void> validate(const SurfaceForce& f, size_t position, const RequestContext& context);
/// The surface load and the pressure.
Result<void> validate_loads(const Vec3& surface_load, double pressure);

/// A number as validation messages show it: the shortest form that reads back as it, or "NaN",
/// "inf", "-inf".
std::string describe_number(double v);

}  // namespace softshell
