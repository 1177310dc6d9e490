#pragma once
/// \file
/// \brief Stresses of a solved deformation: membrane forces, bending moments and von Mises stress
/// at the top and bottom surfaces (linear Kirchhoff-Love shell).

#include <vector>

#include <Eigen/Core>

#include "softshell/engine/shell_model.h"

namespace softshell::engine {

/// Stress state at one surface point, in a local Cartesian frame (e1 along the u tangent, e2 in
/// the tangent plane, normal e3).
struct StressSample {
  SurfacePoint point;
  Vec3 position = Vec3::Zero();               ///< rest limit position
  Eigen::Vector3d membrane_force = Eigen::Vector3d::Zero();  ///< n11, n22, n12 (N/m)
  Eigen::Vector3d bending_moment = Eigen::Vector3d::Zero();  ///< m11, m22, m12 (N m / m)
  double von_mises_top = 0.0;                 ///< Pa, at +t/2 along the normal
  double von_mises_bottom = 0.0;              ///< Pa, at -t/2
  double von_mises() const { return von_mises_top > von_mises_bottom ? von_mises_top : von_mises_bottom; }
};

/// Stresses at a point for a displacement vector (3n). At an extraordinary vertex itself, where
/// the curvature of a Catmull-Clark surface vanishes or diverges, they are taken 2^-10 inside
/// the face (in its (u, v)); the position is the vertex's. Throws Exception(kInvalidArgument) for a
/// bad point or vector size.
StressSample evaluate_stress(const ShellModel& model, const Eigen::VectorXd& displacement, const SurfacePoint& point);

/// The largest von Mises stress over the quadrature points of the whole surface and where it is.
struct StressSummary {
  StressSample max;          ///< the sample with the largest von Mises stress
  bool exceeds_yield = false; ///< max.von_mises() > yield_strength (the linear model is not valid there)
};
StressSummary max_stress(const ShellModel& model, const Eigen::VectorXd& displacement, double yield_strength);

}  // namespace softshell::engine
