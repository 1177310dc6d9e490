#pragma once
/// \file
/// \brief Stresses of a stored deformation: membrane forces, bending moments and von Mises stress
/// at the top and bottom surfaces, computed by the server's engine (`Session::stresses`; HTTP
/// `GET|POST /geometries/{id}/results/{res_id}/stresses`, an extension).

#include <cstdint>
#include <vector>

#include "softshell/control_mesh.h"
#include "softshell/limit_evaluator.h"

namespace softshell {

/// Stress state at one surface point, in a local Cartesian frame (e1 along the u tangent, e2 in
/// the tangent plane, normal e3).
struct StressSample {
  SurfacePoint point;
  Vec3 position = Vec3::Zero();        ///< rest limit position
  Vec3 membrane_force = Vec3::Zero();  ///< n11, n22, n12 (N/m)
  Vec3 bending_moment = Vec3::Zero();  ///< m11, m22, m12 (N m / m)
  double von_mises_top = 0.0;          ///< Pa, at +t/2 along the normal
  double von_mises_bottom = 0.0;       ///< Pa, at -t/2
  double von_mises() const { return von_mises_top > von_mises_bottom ? von_mises_top : von_mises_bottom; }
};

/// Where to evaluate: the vertices of the level-`level` tessellation (1..4, in the order of
/// `Tessellation::vertex_points()`: what a renderer of that level draws), or explicit points.
struct StressQuery {
  static constexpr int kMaxLevel = 4;
  static constexpr size_t kMaxPoints = 1'000'000;
  int level = 0;                      ///< 1..4, or 0 to use `points`
  std::vector<SurfacePoint> points;   ///< used when `level` is 0 (at most kMaxPoints)
  /// Pa: the material's yield strength if the client knows it (a `MaterialPreset` has it; a
  /// geometry stores only E, nu, t), to flag where the linear elastic model stops holding. 0 =
  /// unknown (never flagged).
  double yield_strength = 0.0;
};

/// The stresses of one stored result.
struct StressField {
  uint32_t res_id = 0;
  double yield_strength = 0.0;        ///< Pa, as the query gave it (0 = unknown)
  /// The largest von Mises stress over the whole surface (the quadrature points), and whether
  /// the material yields there (then the linear elastic model does not hold).
  StressSample max;
  bool exceeds_yield = false;
  std::vector<StressSample> samples;  ///< one per queried point, in order
};

}  // namespace softshell
