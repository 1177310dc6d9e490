#include "krylov.h"

#include <cmath>
#include <vector>

#include <Eigen/Dense>

namespace softshell::engine::internal {

KrylovResult gmres(const std::function<Eigen::VectorXd(const Eigen::VectorXd&)>& apply, const Eigen::VectorXd& b,
                   double tolerance, int max_iterations) {
  KrylovResult result;
  result.x = Eigen::VectorXd::Zero(b.size());
  const double beta = b.norm();
  if (!(beta > 0.0)) {
    result.relative_residual = 0.0;
    result.converged = true;
    return result;
  }
  const int k_max = std::max(1, max_iterations);
  std::vector<Eigen::VectorXd> basis{b / beta};
  Eigen::MatrixXd h = Eigen::MatrixXd::Zero(k_max + 1, k_max);
  Eigen::VectorXd cs = Eigen::VectorXd::Zero(k_max), sn = Eigen::VectorXd::Zero(k_max);
  Eigen::VectorXd g = Eigen::VectorXd::Zero(k_max + 1);
  g[0] = beta;
  int k = 0;
  for (; k < k_max; ++k) {
    Eigen::VectorXd w = apply(basis[static_cast<size_t>(k)]);
    // Modified Gram-Schmidt, twice (the basis must stay orthogonal to round-off).
    for (int pass = 0; pass < 2; ++pass) {
      for (int i = 0; i <= k; ++i) {
        const double c = basis[static_cast<size_t>(i)].dot(w);
        h(i, k) += c;
        w -= c * basis[static_cast<size_t>(i)];
      }
    }
    h(k + 1, k) = w.norm();
    for (int i = 0; i < k; ++i) {  // earlier rotations
      const double t = cs[i] * h(i, k) + sn[i] * h(i + 1, k);
      h(i + 1, k) = -sn[i] * h(i, k) + cs[i] * h(i + 1, k);
      h(i, k) = t;
    }
    const double r = std::hypot(h(k, k), h(k + 1, k));
    cs[k] = r > 0.0 ? h(k, k) / r : 1.0;
    sn[k] = r > 0.0 ? h(k + 1, k) / r : 0.0;
    const double sub = h(k + 1, k);
    h(k, k) = r;
    h(k + 1, k) = 0.0;
    g[k + 1] = -sn[k] * g[k];
    g[k] = cs[k] * g[k];
    result.relative_residual = std::abs(g[k + 1]) / beta;
    if (result.relative_residual <= tolerance || !(sub > 1e-14 * r)) {
      ++k;
      break;
    }
    basis.push_back(w / sub);
  }
  result.iterations = k;
  result.converged = result.relative_residual <= tolerance;
  // y = H^-1 g on the leading k x k upper-triangular block.
  const Eigen::VectorXd y = h.topLeftCorner(k, k).triangularView<Eigen::Upper>().solve(g.head(k));
  for (int i = 0; i < k; ++i) result.x += y[i] * basis[static_cast<size_t>(i)];
  if (!result.x.allFinite()) {
    result.x.setZero();
    result.converged = false;
    result.relative_residual = 1.0;
  }
  return result;
}

}  // namespace softshell::engine::internal
