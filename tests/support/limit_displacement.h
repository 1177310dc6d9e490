#pragma once
// The displacement of a point of the limit surface from control-point displacements, for tests
// that compare answers at surface points (one copy instead of one per test file).

#include <Eigen/Core>

#include "softshell/limit_evaluator.h"

namespace softshell::test {

/// sum_k w_k u_k over the limit stencil at `p` (u: 3n, DOF 3i + a is axis a of point i).
inline Vec3 limit_displacement(const LimitEvaluator& limit, const Eigen::VectorXd& u, const SurfacePoint& p) {
  const LimitStencil st = limit.stencil(p);
  Vec3 d = Vec3::Zero();
  for (size_t k = 0; k < st.size(); ++k) d += st.position[k] * u.segment<3>(3 * st.indices[k]);
  return d;
}

/// The same on a model's evaluator (any type with `evaluator()`, e.g. engine::ShellModel).
template <class Model>
Vec3 limit_displacement(const Model& model, const Eigen::VectorXd& u, const SurfacePoint& p) {
  return limit_displacement(model.evaluator(), u, p);
}

}  // namespace softshell::test
