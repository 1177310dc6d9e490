#pragma once
/// \file
/// \brief `DeformationRequest` (forces and constraints) and `DeformationResult`: what a client
/// asks the server to solve and what it gets back (PROTOCOL.md, `POST /geometries/{id}/results`).

#include <cstdint>
#include <optional>
#include <vector>

#include "softshell/control_mesh.h"
#include "softshell/limit_evaluator.h"

namespace softshell {

/// Axis bits of a vertex constraint mask.
enum AxisMask : uint32_t { kAxisX = 1, kAxisY = 2, kAxisZ = 4, kAxisAll = 7 };

/// Prescribes the displacement of one control point on the axes set in `mask` (1..7).
struct VertexConstraint {
  int32_t index = 0;                     ///< control point
  uint32_t mask = kAxisAll;              ///< bits: 1 = x, 2 = y, 4 = z
  Vec3 displacement = Vec3::Zero();      ///< prescribed displacement (length unit); unset axes ignored
};

/// Three scalar equations, one per axis a: sum_j coefficients[j][a] * u[indices[j]][a] = values[a]
/// (the paper's Equation 3). An equation whose coefficients are all zero is dropped if its value
/// is zero and is an error otherwise.
struct LagrangeConstraint {
  std::vector<int32_t> indices;   ///< control points
  std::vector<Vec3> coefficients; ///< one triple per index
  Vec3 values = Vec3::Zero();     ///< right-hand sides per axis
};

/// A force on one control point (N in SI); repeated indices add up.
struct PointForce {
  int32_t index = 0;
  Vec3 force = Vec3::Zero();
};

/// A force at a point of the limit surface, spread over control points with the limit weights
/// (f_A = N_A(p) F). JSON extension `surface_forces`.
struct SurfaceForce {
  SurfacePoint point;
  Vec3 force = Vec3::Zero();
};

/// Moves the limit surface point `point` by `displacement`; optionally also prescribes the change
/// of the tangents d(x)/du and d(x)/dv there (to control the tangent plane, paper Section 6.2).
/// JSON extension `limit_constraints` (tangents: `du_displacement`, `dv_displacement`).
struct LimitConstraint {
  SurfacePoint point;
  Vec3 displacement = Vec3::Zero();
  std::optional<Vec3> du_displacement;  ///< change of the u tangent, if prescribed
  std::optional<Vec3> dv_displacement;  ///< change of the v tangent, if prescribed
};

/// The mechanical model a request is solved with (PROTOCOL.md version 2, "The nonlinear model").
enum class DeformationModel : uint8_t {
  kLinear,     ///< the linear Kirchhoff-Love shell (small displacements; the paper's model)
  kNonlinear,  ///< the geometrically nonlinear shell (large displacements and rotations)
};

/// Everything a deformation request can carry. Forces and loads are in N (SI), areas in the
/// mesh's length unit squared.
struct DeformationRequest {
  std::vector<VertexConstraint> vertex_constraints;
  std::vector<LagrangeConstraint> lagrange_constraints;
  std::vector<PointForce> forces;
  // JSON-only extensions (the binary layout cannot carry them):
  std::vector<LimitConstraint> limit_constraints;
  std::vector<SurfaceForce> surface_forces;
  Vec3 surface_load = Vec3::Zero();  ///< force per unit area of the limit surface, f_A = ∫ N_A q dA
  double pressure = 0.0;             ///< force per unit area along the unit normal (counter-clockwise side)
  /// JSON field `model` (or the query parameter `model=` with either layout; the binary body
  /// cannot carry it). With kNonlinear, `pressure` follows the deformed normal.
  DeformationModel model = DeformationModel::kLinear;

  /// True if only the fields of the binary layout are used (a nonlinear request does not fit:
  /// the binary body alone would be solved with the linear model).
  bool fits_binary_layout() const {
    return limit_constraints.empty() && surface_forces.empty() && surface_load.isZero(0.0) && pressure == 0.0 &&
           model == DeformationModel::kLinear;
  }
  bool empty() const {
    return vertex_constraints.empty() && lagrange_constraints.empty() && forces.empty() && limit_constraints.empty() &&
           surface_forces.empty() && surface_load.isZero(0.0) && pressure == 0.0;
  }
};

/// A stored deformation: its id in the geometry's history and the deformed control points.
struct DeformationResult {
  uint32_t res_id = 0;            ///< 1, 2, 3, ... per geometry, in the order stored
  std::vector<Vec3> positions;    ///< deformed control point positions (#V)
  /// The model it was solved with; for kNonlinear the JSON layout adds `iterations` and
  /// `residual` (the binary layout carries neither).
  DeformationModel model = DeformationModel::kLinear;
  int32_t iterations = 0;  ///< Newton iterations (nonlinear model)
  double residual = 0.0;   ///< relative out-of-balance force at the answer (nonlinear model)
};

}  // namespace softshell
