#include "kirchhoff_love.h"

#include <cmath>

namespace softshell::engine::internal {

bool compute_frame(const Eigen::Ref<const Eigen::MatrixXd>& w, const Eigen::Ref<const Eigen::MatrixX3d>& x,
                   double youngs_modulus, double poisson_ratio, SurfaceFrame& out) {
  out.a1 = (w.row(1) * x).transpose();
  out.a2 = (w.row(2) * x).transpose();
  out.a11 = (w.row(3) * x).transpose();
  out.a12 = (w.row(4) * x).transpose();
  out.a22 = (w.row(5) * x).transpose();
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

void strain_matrices(const Eigen::Ref<const Eigen::MatrixXd>& w, const SurfaceFrame& f, Matrix3Xd& bm,
                     Matrix3Xd& bb) {
  const Eigen::Index m = w.cols();
  bm.resize(3, 3 * m);
  bb.resize(3, 3 * m);
  const double inv_j = 1.0 / f.j;
  for (Eigen::Index a = 0; a < m; ++a) {
    const double n1 = w(1, a), n2 = w(2, a), n11 = w(3, a), n12 = w(4, a), n22 = w(5, a);
    for (int i = 0; i < 3; ++i) {
      const Eigen::Index col = 3 * a + i;
      // Membrane: e_ab = 1/2 (a_a . u,b + a_b . u,a).
      bm(0, col) = n1 * f.a1[i];
      bm(1, col) = n2 * f.a2[i];
      bm(2, col) = n1 * f.a2[i] + n2 * f.a1[i];
      // Bending: variation of b_ab = a_a,b . n, with the normal's variation projected onto the
      // tangent plane (the term that vanishes on flat plates).
      Vec3 e = Vec3::Zero();
      e[i] = 1.0;
      const Vec3 da3 = n1 * e.cross(f.a2) + n2 * f.a1.cross(e);
      const Vec3 dn = (da3 - f.a3 * f.a3.dot(da3)) * inv_j;
      const double db11 = n11 * f.a3[i] + f.a11.dot(dn);
      const double db22 = n22 * f.a3[i] + f.a22.dot(dn);
      const double db12 = n12 * f.a3[i] + f.a12.dot(dn);
      bb(0, col) = -db11;
      bb(1, col) = -db22;
      bb(2, col) = -2.0 * db12;
    }
  }
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
