#include "softshell/engine/nonlinear_stresses.h"

#include <array>
#include <cmath>
#include <map>
#include <string>
#include <vector>

#include "kirchhoff_love.h"
#include "stress_scan.h"

namespace softshell::engine {
namespace {

double von_mises(const Eigen::Vector3d& s) {  // plane stress [s11, s22, s12]
  return std::sqrt(std::max(0.0, s[0] * s[0] + s[1] * s[1] - s[0] * s[1] + 3.0 * s[2] * s[2]));
}

// Components in the local Cartesian frame (e1 along a1, e2 in the plane) of the tensor
// T^ab a_a (x) a_b given by its contravariant Voigt components [T^11, T^22, T^12].
Eigen::Vector3d cartesian_components(const Eigen::Vector3d& contravariant, const Vec3& a1, const Vec3& a2, const Vec3& n) {
  const Vec3 e1 = a1.normalized(), e2 = n.cross(e1).normalized();
  const double p11 = e1.dot(a1), p12 = e1.dot(a2), p21 = e2.dot(a1), p22 = e2.dot(a2);  // e_i . a_a
  const double t11 = contravariant[0], t22 = contravariant[1], t12 = contravariant[2];
  auto component = [&](double pi1, double pi2, double pj1, double pj2) {
    return t11 * pi1 * pj1 + t22 * pi2 * pj2 + t12 * (pi1 * pj2 + pi2 * pj1);
  };
  return Eigen::Vector3d(component(p11, p12, p11, p12), component(p21, p22, p21, p22), component(p11, p12, p21, p22));
}

void face_stresses(const ShellModel& model, const Eigen::VectorXd& u, int32_t face, int32_t subface,
                   const std::vector<std::array<double, 2>>& uvs, std::vector<NonlinearStressSample>& out) {
  std::vector<int32_t> indices;
  Eigen::MatrixXd basis;
  model.evaluator().face_stencils(face, subface, uvs, indices, basis);
  const auto m = static_cast<Eigen::Index>(indices.size());
  Eigen::MatrixX3d x(m, 3), d(m, 3);
  for (Eigen::Index a = 0; a < m; ++a) {
    const auto idx = static_cast<size_t>(indices[static_cast<size_t>(a)]);
    x.row(a) = model.mesh().positions()[idx].transpose();
    d.row(a) = u.segment<3>(static_cast<Eigen::Index>(3 * idx)).transpose();
  }
  const Material& mat = model.material();
  const double t = mat.thickness, nu = mat.poisson_ratio;
  Eigen::Matrix3d plane;  // Cartesian plane-stress matrix
  plane << 1.0, nu, 0.0, nu, 1.0, 0.0, 0.0, 0.0, 0.5 * (1.0 - nu);
  plane *= mat.youngs_modulus / (1.0 - nu * nu);
  internal::SurfaceFrame frame;
  for (size_t q = 0; q < uvs.size(); ++q) {
    const auto w = basis.middleRows(static_cast<Eigen::Index>(6 * q), 6);
    NonlinearStressSample s;
    s.point = SurfacePoint{face, subface, uvs[q][0], uvs[q][1]};
    const Eigen::Matrix<double, 6, 3> ref = w * x, du = w * d;  // rows: x, x,u, x,v, x,uu, x,uv, x,vv
    s.position = (ref.row(0) + du.row(0)).transpose();
    if (!internal::compute_frame(w, x, mat.youngs_modulus, nu, frame)) {
      out.push_back(s);
      continue;
    }
    const Vec3 A1 = ref.row(1), A2 = ref.row(2), d1 = du.row(1), d2 = du.row(2);
    const Vec3 a1 = A1 + d1, a2 = A2 + d2;
    const Vec3 t3 = a1.cross(a2);
    const double j = t3.norm();
    if (!(j > 0.0)) fail(ErrorCode::kUnprocessable, "nonlinear stresses: the deformed surface is degenerate at face " + std::to_string(face));
    const Vec3 n = t3 / j;
    // Green-Lagrange strains and curvature change, as in the nonlinear kernel.
    const Eigen::Vector3d e(A1.dot(d1) + 0.5 * d1.squaredNorm(), A2.dot(d2) + 0.5 * d2.squaredNorm(),
                            A1.dot(d2) + d1.dot(A2) + d1.dot(d2));
    const Eigen::Vector3d k(ref.row(3).dot(frame.a3) - (ref.row(3) + du.row(3)).dot(n),
                            ref.row(5).dot(frame.a3) - (ref.row(5) + du.row(5)).dot(n),
                            2.0 * (ref.row(4).dot(frame.a3) - (ref.row(4) + du.row(4)).dot(n)));
    // Second Piola-Kirchhoff: in the reference frame as the linear model reports its stresses.
    const Eigen::Matrix3d to_cartesian = internal::cartesian_strain_transform(frame);
    s.green_lagrange_strain = to_cartesian * e;
    s.curvature_change = to_cartesian * k;
    s.pk2_membrane_force = t * plane * s.green_lagrange_strain;
    s.pk2_bending_moment = (t * t * t / 12.0) * plane * s.curvature_change;
    // Cauchy: the contravariant resultants push forward with the deformed tangents, per unit
    // deformed area (1 / (j / J)).
    const Eigen::Vector3d n_contra = t * frame.material * e, m_contra = (t * t * t / 12.0) * frame.material * k;
    const double stretch = j / frame.j;
    s.cauchy_membrane_force = cartesian_components(n_contra, a1, a2, n) / stretch;
    s.cauchy_bending_moment = cartesian_components(m_contra, a1, a2, n) / stretch;
    // sigma(z) = n / t + z 12 m / t^3 at z = +-t/2 along the deformed normal.
    const Eigen::Vector3d mean = s.cauchy_membrane_force / t, bend = 6.0 * s.cauchy_bending_moment / (t * t);
    s.von_mises_top = von_mises(mean + bend);
    s.von_mises_bottom = von_mises(mean - bend);
    out.push_back(s);
  }
}

void check_size(const ShellModel& model, const Eigen::VectorXd& u) {
  if (u.size() != model.num_dofs()) {
    fail(ErrorCode::kInvalidArgument, "stresses: the displacement vector has " + std::to_string(u.size()) +
                                          " entries, the model " + std::to_string(model.num_dofs()));
  }
  if (!u.allFinite()) fail(ErrorCode::kInvalidArgument, "stresses: the displacement vector has a NaN or infinite entry");
}

}  // namespace

NonlinearStressSample evaluate_nonlinear_stress(const ShellModel& model, const Eigen::VectorXd& displacement,
                                                const SurfacePoint& point) {
  check_size(model, displacement);
  model.evaluator().check(point).value();
  std::vector<NonlinearStressSample> out;
  face_stresses(model, displacement, point.face, point.subface, {{point.u, point.v}}, out);
  return out.front();
}

NonlinearStressSummary nonlinear_max_stress(const ShellModel& model, const Eigen::VectorXd& displacement,
                                            double yield_strength) {
  check_size(model, displacement);
  NonlinearStressSummary summary;
  summary.max = internal::max_von_mises_at_quadrature_points<NonlinearStressSample>(
      model, [&](int32_t face, int32_t subface, const std::vector<std::array<double, 2>>& uvs,
                 std::vector<NonlinearStressSample>& out) { face_stresses(model, displacement, face, subface, uvs, out); });
  summary.exceeds_yield = summary.max.von_mises() > yield_strength;
  return summary;
}

}  // namespace softshell::engine
