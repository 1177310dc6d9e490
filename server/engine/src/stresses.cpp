#include "softshell/engine/stresses.h"

#include <array>
#include <cmath>
#include <map>
#include <string>

#include "kirchhoff_love.h"
#include "stress_scan.h"

namespace softshell::engine {
namespace {

double von_mises(const Eigen::Vector3d& s) {  // plane stress [s11, s22, s12]
  return std::sqrt(std::max(0.0, s[0] * s[0] + s[1] * s[1] - s[0] * s[1] + 3.0 * s[2] * s[2]));
}

// At an extraordinary vertex itself the curvature of the limit surface, and of every basis
// function, vanishes or diverges: the stress there is taken 2^-10 inside the face (the membrane
// part is continuous; the bending part is that of the field next to the vertex).
std::array<double, 2> stress_point(const LimitEvaluator& evaluator, int32_t face, int32_t subface, std::array<double, 2> uv) {
  const bool corner_u = uv[0] == 0.0 || uv[0] == 1.0, corner_v = uv[1] == 0.0 || uv[1] == 1.0;
  if (!corner_u || !corner_v) return uv;
  const int corner = uv[1] == 0.0 ? (uv[0] == 0.0 ? 0 : 1) : (uv[0] == 1.0 ? 2 : 3);
  std::vector<double> unused;
  if (!evaluator.ev_corner_weights(face, subface, corner, 0.5, 1, unused)) return uv;
  constexpr double kInside = 1.0 / 1024.0;
  return {uv[0] == 0.0 ? kInside : 1.0 - kInside, uv[1] == 0.0 ? kInside : 1.0 - kInside};
}

// Stresses at the points `uvs` of one (sub-)face.
void face_stresses(const ShellModel& model, const Eigen::VectorXd& u, int32_t face, int32_t subface,
                   const std::vector<std::array<double, 2>>& uvs, std::vector<StressSample>& out) {
  std::vector<int32_t> indices;
  Eigen::MatrixXd basis;
  std::vector<std::array<double, 2>> at(uvs.size());
  for (size_t q = 0; q < uvs.size(); ++q) at[q] = stress_point(model.evaluator(), face, subface, uvs[q]);
  model.evaluator().face_stencils(face, subface, at, indices, basis);
  const auto m = static_cast<Eigen::Index>(indices.size());
  Eigen::MatrixX3d x(m, 3);
  Eigen::VectorXd local(3 * m);
  for (Eigen::Index a = 0; a < m; ++a) {
    const auto idx = static_cast<size_t>(indices[static_cast<size_t>(a)]);
    x.row(a) = model.mesh().positions()[idx].transpose();
    local.segment<3>(3 * a) = u.segment<3>(static_cast<Eigen::Index>(3 * idx));
  }
  const Material& mat = model.material();
  const double t = mat.thickness, nu = mat.poisson_ratio;
  Eigen::Matrix3d plane;  // Cartesian plane-stress matrix
  plane << 1.0, nu, 0.0, nu, 1.0, 0.0, 0.0, 0.0, 0.5 * (1.0 - nu);
  plane *= mat.youngs_modulus / (1.0 - nu * nu);
  internal::SurfaceFrame frame;
  internal::Matrix3Xd bm, bb;
  for (size_t q = 0; q < uvs.size(); ++q) {
    const auto w = basis.middleRows(static_cast<Eigen::Index>(6 * q), 6);
    StressSample s;
    s.point = SurfacePoint{face, subface, uvs[q][0], uvs[q][1]};
    s.position = at[q] == uvs[q] ? Vec3((w.row(0) * x).transpose()) : model.evaluator().evaluate(s.point).position;
    if (internal::compute_frame(w, x, mat.youngs_modulus, nu, frame)) {
      internal::strain_matrices(w, frame, bm, bb);
      const Eigen::Matrix3d to_cartesian = internal::cartesian_strain_transform(frame);
      const Eigen::Vector3d strain = to_cartesian * (bm * local);     // [E11, E22, 2 E12]
      const Eigen::Vector3d curvature = to_cartesian * (bb * local);  // [K11, K22, 2 K12]
      s.membrane_force = t * plane * strain;
      s.bending_moment = (t * t * t / 12.0) * plane * curvature;
      // sigma(z) = n / t + z 12 m / t^3 at z = +-t/2 along the normal.
      const Eigen::Vector3d mean = s.membrane_force / t, bend = 6.0 * s.bending_moment / (t * t);
      s.von_mises_top = von_mises(mean + bend);
      s.von_mises_bottom = von_mises(mean - bend);
    }
    out.push_back(s);
  }
}

void check_size(const ShellModel& model, const Eigen::VectorXd& u) {
  if (u.size() != model.num_dofs()) {
    fail(ErrorCode::kInvalidArgument, "stresses: the displacement vector has " + std::to_string(u.size()) +
                                          " entries, the model " + std::to_string(model.num_dofs()));
  }
}

}  // namespace

StressSample evaluate_stress(const ShellModel& model, const Eigen::VectorXd& displacement, const SurfacePoint& point) {
  check_size(model, displacement);
  model.evaluator().check(point).value();
  std::vector<StressSample> out;
  face_stresses(model, displacement, point.face, point.subface, {{point.u, point.v}}, out);
  return out.front();
}

std::vector<StressSample> evaluate_stresses(const ShellModel& model, const Eigen::VectorXd& displacement,
                                            const std::vector<SurfacePoint>& points) {
  check_size(model, displacement);
  // Points grouped by (face, sub-face), remembering where each goes.
  std::map<std::pair<int32_t, int32_t>, std::pair<std::vector<std::array<double, 2>>, std::vector<size_t>>> groups;
  for (size_t i = 0; i < points.size(); ++i) {
    model.evaluator().check(points[i]).value();
    auto& [uvs, slots] = groups[{points[i].face, points[i].subface}];
    uvs.push_back({points[i].u, points[i].v});
    slots.push_back(i);
  }
  std::vector<StressSample> out(points.size()), samples;
  for (const auto& [key, group] : groups) {
    samples.clear();
    face_stresses(model, displacement, key.first, key.second, group.first, samples);
    for (size_t k = 0; k < samples.size(); ++k) out[group.second[k]] = samples[k];
  }
  return out;
}

StressSummary max_stress(const ShellModel& model, const Eigen::VectorXd& displacement, double yield_strength) {
  check_size(model, displacement);
  StressSummary summary;
  summary.max = internal::max_von_mises_at_quadrature_points<StressSample>(
      model, [&](int32_t face, int32_t subface, const std::vector<std::array<double, 2>>& uvs, std::vector<StressSample>& out) {
        face_stresses(model, displacement, face, subface, uvs, out);
      });
  summary.exceeds_yield = summary.max.von_mises() > yield_strength;
  return summary;
}

}  // namespace softshell::engine
