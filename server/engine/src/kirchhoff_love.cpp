#include "kirchhoff_love.h"

#include <cmath>

namespace softshell::engine::internal {

bool compute_frame(const Eigen::Ref<const Eigen::MatrixXd>& w, const Eigen::Ref<const Eigen::MatrixX3d>& x,
                   double youngs_modulus, double poisson_ratio, SurfaceFrame& out) {
  Eigen::Matrix<double, 6, 3> derivatives;  // x, x,u, x,v, x,uu, x,uv, x,vv as rows
  derivatives.noalias() = w * x;
  out.a1 = derivatives.row(1).transpose();
  out.a2 = derivatives.row(2).transpose();
  out.a11 = derivatives.row(3).transpose();
  out.a12 = derivatives.row(4).transpose();
  out.a22 = derivatives.row(5).transpose();
  const Vec3 a3_tilde = out.a1.cross(out.a2);
  out.j = a3_tilde.norm();
  if (!(out.j > 0.0) || !std::isfinite(out.j)) return false;
  out.a3 = a3_tilde / out.j;

  // Contravariant metric a^{ab} = (a_ab)^-1.
  const double g11 = out.a1.dot(out.a1), g22 = out.a2.dot(out.a2), g12 = out.a1.dot(out.a2);
  const double det = g11 * g22 - g12 * g12;
  const double h11 = g22 / det, h22 = g11 / det, h12 = -g12 / det;
  const double nu = poisson_ratio;
  const double factor = youngs_modulus / (1.0 - nu * nu);
  Eigen::Matrix3d& c = out.material;
  c(0, 0) = h11 * h11;
  c(0, 1) = nu * h11 * h22 + (1.0 - nu) * h12 * h12;
  c(0, 2) = h11 * h12;
  c(1, 1) = h22 * h22;
  c(1, 2) = h22 * h12;
  c(2, 2) = 0.5 * ((1.0 - nu) * h11 * h22 + (1.0 + nu) * h12 * h12);
  c(1, 0) = c(0, 1);
  c(2, 0) = c(0, 2);
  c(2, 1) = c(1, 2);
  c *= factor;
  return true;
}

namespace {

// Calls out(col, membrane_column, bending_column) for every DOF column 3A + i of the strain-
// displacement matrices. A unit displacement e_i of a control point with derivative weights
// (N,1, N,2) changes the unnormalized normal by N,1 (e_i x a2) + N,2 (a1 x e_i); the unit normal
// by that projected onto the tangent plane, divided by j (the term that vanishes on flat plates).
// Everything but the weights is the same for all control points, so the dot products with a_ab
// are taken once.
template <class Out>
void for_each_strain_column(const Eigen::Ref<const Eigen::MatrixXd>& w, const SurfaceFrame& f, Out&& out) {
  Eigen::Matrix3d c, d;  // columns: e_i x a2, a1 x e_i
  c << 0.0, f.a2.z(), -f.a2.y(),  //
      -f.a2.z(), 0.0, f.a2.x(),   //
      f.a2.y(), -f.a2.x(), 0.0;
  d << 0.0, -f.a1.z(), f.a1.y(),  //
      f.a1.z(), 0.0, -f.a1.x(),   //
      -f.a1.y(), f.a1.x(), 0.0;
  const Eigen::Matrix3d projection = (Eigen::Matrix3d::Identity() - f.a3 * f.a3.transpose()) / f.j;
  const Eigen::Matrix3d pc = projection * c, pd = projection * d;
  // a_ab . dn for a unit N,1 (g) and a unit N,2 (h), per axis i.
  const Eigen::RowVector3d g11 = f.a11.transpose() * pc, h11 = f.a11.transpose() * pd;
  const Eigen::RowVector3d g22 = f.a22.transpose() * pc, h22 = f.a22.transpose() * pd;
  const Eigen::RowVector3d g12 = f.a12.transpose() * pc, h12 = f.a12.transpose() * pd;
  for (Eigen::Index a = 0; a < w.cols(); ++a) {
    const double n1 = w(1, a), n2 = w(2, a), n11 = w(3, a), n12 = w(4, a), n22 = w(5, a);
    for (int i = 0; i < 3; ++i) {
      // Membrane: e_ab = 1/2 (a_a . u,b + a_b . u,a).
      const Eigen::Vector3d membrane(n1 * f.a1[i], n2 * f.a2[i], n1 * f.a2[i] + n2 * f.a1[i]);
      // Bending: minus the variation of b_ab = a_a,b . n.
      const Eigen::Vector3d bending(-(n11 * f.a3[i] + n1 * g11[i] + n2 * h11[i]),
                                    -(n22 * f.a3[i] + n1 * g22[i] + n2 * h22[i]),
                                    -2.0 * (n12 * f.a3[i] + n1 * g12[i] + n2 * h12[i]));
      out(3 * a + i, membrane, bending);
    }
  }
}

}  // namespace

void strain_matrices(const Eigen::Ref<const Eigen::MatrixXd>& w, const SurfaceFrame& f, Matrix3Xd& bm,
                     Matrix3Xd& bb) {
  bm.resize(3, 3 * w.cols());
  bb.resize(3, 3 * w.cols());
  for_each_strain_column(w, f, [&](Eigen::Index col, const Eigen::Vector3d& membrane, const Eigen::Vector3d& bending) {
    bm.col(col) = membrane;
    bb.col(col) = bending;
  });
}

void weighted_strain_rows(const Eigen::Ref<const Eigen::MatrixXd>& w, const SurfaceFrame& f,
                          const Eigen::Matrix3d& membrane_weight, const Eigen::Matrix3d& bending_weight,
                          Eigen::Ref<Eigen::MatrixXd> out) {
  for_each_strain_column(w, f, [&](Eigen::Index col, const Eigen::Vector3d& membrane, const Eigen::Vector3d& bending) {
    out.block<3, 1>(0, col).noalias() = membrane_weight * membrane;
    out.block<3, 1>(3, col).noalias() = bending_weight * bending;
  });
}

Eigen::Matrix3d cartesian_strain_transform(const SurfaceFrame& f) {
  // e1 = a1/|a1|, e2 = a^2/|a^2| (contravariant base vector), G_ia = e_i . a^a.
  const double g11 = f.a1.dot(f.a1), g22 = f.a2.dot(f.a2), g12 = f.a1.dot(f.a2);
  const double det = g11 * g22 - g12 * g12;
  const Vec3 a_up1 = (g22 * f.a1 - g12 * f.a2) / det;
  const Vec3 a_up2 = (-g12 * f.a1 + g11 * f.a2) / det;
  const Vec3 e1 = f.a1.normalized();
  const Vec3 e2 = a_up2.normalized();
  const double G11 = e1.dot(a_up1), G12 = e1.dot(a_up2), G21 = e2.dot(a_up1), G22 = e2.dot(a_up2);
  Eigen::Matrix3d t;
  // Maps curvilinear [e11, e22, 2 e12] to Cartesian [E11, E22, 2 E12]: E_ij = G_ia G_jb e_ab.
  t << G11 * G11, G12 * G12, G11 * G12,
       G21 * G21, G22 * G22, G21 * G22,
       2 * G11 * G21, 2 * G12 * G22, G11 * G22 + G12 * G21;
  return t;
}

}  // namespace softshell::engine::internal
