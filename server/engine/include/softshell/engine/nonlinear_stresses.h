#pragma once
/// \file
/// \brief Stresses of a nonlinear (large-displacement) result: second Piola-Kirchhoff stress
/// resultants from the Green-Lagrange strains and the change of curvature, and the Cauchy (true)
/// stresses of the deformed surface (what the demo colours).

#include <Eigen/Core>

#include "softshell/engine/shell_model.h"

namespace softshell::engine {

/// Stress state at one surface point of a nonlinear result.
///
/// Second Piola-Kirchhoff resultants are per unit reference length in the reference local
/// Cartesian frame (e1 along the reference u tangent, e2 in the tangent plane): the linear model's
/// frame, and in the limit of small displacements the linear model's values. Cauchy resultants are
/// per unit deformed length in the deformed local frame (e1 along the deformed u tangent). St.
/// Venant-Kirchhoff plane stress with the model's E, nu, t; the thickness change of a strain of a
/// few percent is neglected.
struct NonlinearStressSample {
  SurfacePoint point;
  Vec3 position = Vec3::Zero();  ///< deformed limit position
  Eigen::Vector3d green_lagrange_strain = Eigen::Vector3d::Zero();   ///< E11, E22, 2 E12 (reference frame)
  Eigen::Vector3d curvature_change = Eigen::Vector3d::Zero();        ///< K11, K22, 2 K12 (1/m, reference frame)
  Eigen::Vector3d pk2_membrane_force = Eigen::Vector3d::Zero();      ///< n11, n22, n12 (N/m)
  Eigen::Vector3d pk2_bending_moment = Eigen::Vector3d::Zero();      ///< m11, m22, m12 (N m / m)
  Eigen::Vector3d cauchy_membrane_force = Eigen::Vector3d::Zero();   ///< n11, n22, n12 (N/m), deformed frame
  Eigen::Vector3d cauchy_bending_moment = Eigen::Vector3d::Zero();   ///< m11, m22, m12 (N m / m), deformed frame
  double von_mises_top = 0.0;     ///< Cauchy, Pa, at +t/2 along the deformed normal
  double von_mises_bottom = 0.0;  ///< Cauchy, Pa, at -t/2
  double von_mises() const { return von_mises_top > von_mises_bottom ? von_mises_top : von_mises_bottom; }
};

/// Stresses at a point for a displacement vector (3n) of the nonlinear model. Throws
/// Exception(kInvalidArgument) for a bad point or vector size, kUnprocessable where the deformed
/// surface is degenerate.
NonlinearStressSample evaluate_nonlinear_stress(const ShellModel& model, const Eigen::VectorXd& displacement,
                                                const SurfacePoint& point);

/// The largest (Cauchy) von Mises stress over the quadrature points of the whole surface.
struct NonlinearStressSummary {
  NonlinearStressSample max;
  bool exceeds_yield = false;  ///< max.von_mises() > yield_strength
};
NonlinearStressSummary nonlinear_max_stress(const ShellModel& model, const Eigen::VectorXd& displacement,
                                            double yield_strength);

}  // namespace softshell::engine
