#pragma once
// Linear Kirchhoff-Love shell kinematics at one point of the limit surface (pure numerics).
//
// Notation follows shell-theory notes §1 (Kiendl et al. 2009): a_alpha are the covariant tangents,
// a3 the unit normal, a^{alpha beta} the contravariant metric and b_{alpha beta} the curvature.
// Strains are Voigt vectors with the engineering shear: [e11, e22, 2 e12], [k11, k22, 2 k12].

#include <Eigen/Core>

#include "softshell/control_mesh.h"
#include "softshell/material.h"

namespace softshell::engine::internal {

using Matrix3Xd = Eigen::Matrix<double, 3, Eigen::Dynamic>;

/// Geometry of the reference surface at one point.
struct SurfaceFrame {
  Vec3 a1, a2, a11, a22, a12;  // first and second derivatives of the position
  Vec3 a3;                     // unit normal
  double j = 0.0;              // |a1 x a2|: area element
  Eigen::Matrix3d material;    // contravariant plane-stress matrix C (without the thickness factor)
};

/// Computes the frame from the basis weights `w` (6 x m: N, N,u, N,v, N,uu, N,uv, N,vv) and the
/// control points `x` (m x 3). Returns false where the surface is degenerate (j == 0).
bool compute_frame(const Eigen::Ref<const Eigen::MatrixXd>& w, const Eigen::Ref<const Eigen::MatrixX3d>& x,
                   double youngs_modulus, double poisson_ratio, SurfaceFrame& out);

/// Membrane (Bm) and bending (Bb) strain-displacement matrices, 3 x 3m each: column 3A + i is the
/// strain caused by a unit displacement of control point A along axis i.
void strain_matrices(const Eigen::Ref<const Eigen::MatrixXd>& w, const SurfaceFrame& frame, Matrix3Xd& bm,
                     Matrix3Xd& bb);

/// The 6 x 3m rows [Wm Bm; Wb Bb] written into `out`, without forming Bm and Bb (the element
/// stiffness is then out^T out when Wm^T Wm and Wb^T Wb are the weighted material matrices).
void weighted_strain_rows(const Eigen::Ref<const Eigen::MatrixXd>& w, const SurfaceFrame& frame,
                          const Eigen::Matrix3d& membrane_weight, const Eigen::Matrix3d& bending_weight,
                          Eigen::Ref<Eigen::MatrixXd> out);

/// Local Cartesian transformation (e1 along a1, e2 in the tangent plane): maps curvilinear Voigt
/// strains [e11, e22, 2e12] to Cartesian ones.
Eigen::Matrix3d cartesian_strain_transform(const SurfaceFrame& frame);

}  // namespace softshell::engine::internal
