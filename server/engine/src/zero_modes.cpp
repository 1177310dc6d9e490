#include "zero_modes.h"

#include <algorithm>
#include <cmath>
#include <map>
#include <random>
#include <string>

#include <Eigen/Dense>

#include "softshell/disjoint_sets.h"

#include "factorization.h"

namespace softshell::engine::internal {

Eigen::MatrixXd null_space_of_scaled_gram(const Eigen::SparseMatrix<double>& a, Eigen::Index dense_limit) {
  constexpr double kZero = 1e-11;  // eigenvalues below this are zero (round-off is ~1e-15)
  constexpr double kClear = 1e-8;  // and the smallest non-zero one must be above this (seen: >= 9e-6)
  const Eigen::Index n = a.rows();
  {
    const internal::SparseCholesky factor(a);
    if (factor.ok() && factor.min_pivot() > kClear) return Eigen::MatrixXd(n, 0);
  }
  auto split = [&](const Eigen::VectorXd& values, const Eigen::MatrixXd& vectors, Eigen::Index found) {
    // `values` ascending; the first `found` are zero. A value between the two bounds would be a
    // motion that barely moves the surface: not expected from a spline basis, so say so.
    if (found < values.size() && values[found] <= kClear) {
      fail(ErrorCode::kInternal, "zero-mode analysis: an eigenvalue " + std::to_string(values[found]) +
                                     " of the scaled basis Gram matrix is neither zero nor clearly positive");
    }
    return Eigen::MatrixXd(vectors.leftCols(found));
  };
  if (n <= dense_limit) {
    const Eigen::SelfAdjointEigenSolver<Eigen::MatrixXd> eig{Eigen::MatrixXd(a)};
    Eigen::Index found = 0;
    while (found < n && eig.eigenvalues()[found] < kZero) ++found;
    return split(eig.eigenvalues(), eig.eigenvectors(), found);
  }
  constexpr double kShift = 1e-2 * kClear;
  Eigen::SparseMatrix<double> shifted = a;
  for (Eigen::Index i = 0; i < n; ++i) shifted.coeffRef(i, i) += kShift;
  const internal::SparseCholesky factor(shifted);
  if (!factor.ok()) fail(ErrorCode::kInternal, "zero-mode analysis: the shifted Gram matrix is not positive definite");
  std::mt19937 rng(12345);
  std::normal_distribution<double> normal;
  for (Eigen::Index block = 8;; block *= 2) {
    if (block >= n / 2) {  // very many modes: decompose densely
      const Eigen::SelfAdjointEigenSolver<Eigen::MatrixXd> eig{Eigen::MatrixXd(a)};
      Eigen::Index found = 0;
      while (found < n && eig.eigenvalues()[found] < kZero) ++found;
      return split(eig.eigenvalues(), eig.eigenvectors(), found);
    }
    Eigen::MatrixXd x(n, block);
    for (Eigen::Index i = 0; i < x.size(); ++i) x.data()[i] = normal(rng);
    for (int iteration = 0; iteration < 6; ++iteration) {
      x = Eigen::HouseholderQR<Eigen::MatrixXd>(x).householderQ() * Eigen::MatrixXd::Identity(n, block);
      x = factor.solve(x);
    }
    x = Eigen::HouseholderQR<Eigen::MatrixXd>(x).householderQ() * Eigen::MatrixXd::Identity(n, block);
    const Eigen::MatrixXd h = x.transpose() * (a * x);
    const Eigen::SelfAdjointEigenSolver<Eigen::MatrixXd> ritz(0.5 * (h + h.transpose()));
    Eigen::Index found = 0;
    while (found < block && ritz.eigenvalues()[found] < kZero) ++found;
    if (found < block) return split(ritz.eigenvalues(), x * ritz.eigenvectors(), found);
  }
}

// The Gram matrix per part: control points no quadrature point sees move nothing (each is a
// null vector by itself); the others through the null space of the scaled matrix.
void find_extra_zero_modes(const Eigen::SparseMatrix<double>& gram, const std::vector<int32_t>& component_of,
                           const Eigen::MatrixXd& rigid, Eigen::MatrixXd& modes, std::vector<bool>& invisible) {
  const auto components = static_cast<size_t>(rigid.cols() / 6);
  std::vector<std::vector<int32_t>> points(components);
  for (size_t v = 0; v < component_of.size(); ++v) points[static_cast<size_t>(component_of[v])].push_back(static_cast<int32_t>(v));
  const Eigen::VectorXd diagonal = gram.diagonal();
  const double top = diagonal.size() ? diagonal.maxCoeff() : 0.0;
  std::vector<Eigen::VectorXd> extra;
  std::vector<int32_t> local(component_of.size(), -1);
  for (size_t c = 0; c < components; ++c) {
    const auto& own = points[c];
    // Control points no quadrature point sees move nothing; the others through the scaled G.
    std::vector<int32_t> seen, unseen;
    for (int32_t v : own) (diagonal[v] > 1e-14 * top ? seen : unseen).push_back(v);
    for (size_t i = 0; i < seen.size(); ++i) local[static_cast<size_t>(seen[i])] = static_cast<int32_t>(i);
    std::vector<Eigen::Triplet<double>> triplets;
    for (int32_t v : seen) {
      for (Eigen::SparseMatrix<double>::InnerIterator it(gram, v); it; ++it) {
        const int32_t row = local[static_cast<size_t>(it.row())];
        if (row >= 0) {
          triplets.emplace_back(row, local[static_cast<size_t>(v)],
                                it.value() / std::sqrt(diagonal[v] * diagonal[it.row()]));
        }
      }
    }
    for (int32_t v : seen) local[static_cast<size_t>(v)] = -1;
    const auto ns = static_cast<Eigen::Index>(seen.size());
    Eigen::SparseMatrix<double> scaled(ns, ns);
    scaled.setFromTriplets(triplets.begin(), triplets.end());
    const Eigen::MatrixXd null = null_space_of_scaled_gram(scaled);
    if (null.cols() == 0 && unseen.empty()) continue;
    // The candidate modes of this part (3 per null vector) on its DOFs, then orthonormal and
    // orthogonal to its rigid modes.
    const auto m = static_cast<Eigen::Index>(3 * own.size());
    for (size_t i = 0; i < own.size(); ++i) local[static_cast<size_t>(own[i])] = static_cast<int32_t>(i);
    Eigen::MatrixXd candidates = Eigen::MatrixXd::Zero(m, 3 * (null.cols() + static_cast<Eigen::Index>(unseen.size())));
    Eigen::Index column = 0;
    for (Eigen::Index k = 0; k < null.cols(); ++k, column += 3) {
      for (Eigen::Index i = 0; i < ns; ++i) {
        const int32_t v = seen[static_cast<size_t>(i)];
        const double value = null(i, k) / std::sqrt(diagonal[v]);
        for (int a = 0; a < 3; ++a) candidates(3 * local[static_cast<size_t>(v)] + a, column + a) = value;
      }
    }
    for (int32_t v : unseen) {
      for (int a = 0; a < 3; ++a) candidates(3 * local[static_cast<size_t>(v)] + a, column + a) = 1.0;
      column += 3;
    }
    Eigen::MatrixXd r(m, 6);
    for (size_t i = 0; i < own.size(); ++i) r.middleRows<3>(static_cast<Eigen::Index>(3 * i)) = rigid.block(3 * own[i], static_cast<Eigen::Index>(6 * c), 3, 6);
    for (int32_t v : own) local[static_cast<size_t>(v)] = -1;
    const Eigen::ColPivHouseholderQR<Eigen::MatrixXd> qr(r);
    const Eigen::MatrixXd q = Eigen::MatrixXd(qr.householderQ()).leftCols(qr.rank());
    candidates -= q * (q.transpose() * candidates);
    const Eigen::JacobiSVD<Eigen::MatrixXd> svd(candidates, Eigen::ComputeThinU);
    const double largest = svd.singularValues().size() ? svd.singularValues()[0] : 0.0;
    for (Eigen::Index s = 0; s < svd.singularValues().size(); ++s) {
      if (!(svd.singularValues()[s] > 1e-6 * largest)) break;
      Eigen::VectorXd v = Eigen::VectorXd::Zero(static_cast<Eigen::Index>(3 * component_of.size()));
      for (size_t i = 0; i < own.size(); ++i) v.segment<3>(3 * own[i]) = svd.matrixU().block<3, 1>(static_cast<Eigen::Index>(3 * i), s);
      extra.push_back(std::move(v));
    }
  }
  modes = rigid;
  if (extra.empty()) return;
  modes.conservativeResize(Eigen::NoChange, rigid.cols() + static_cast<Eigen::Index>(extra.size()));
  for (size_t e = 0; e < extra.size(); ++e) modes.col(rigid.cols() + static_cast<Eigen::Index>(e)) = extra[e];
  // By construction none of them moves the limit surface at a quadrature point.
  invisible.assign(extra.size(), true);
}

// Surface pieces by shared edges of faces with a limit surface.
void check_surface_connected(const ControlMesh& mesh, const LimitEvaluator& evaluator,
                             const std::vector<int32_t>& component_of) {
  DisjointSets pieces(static_cast<size_t>(mesh.num_faces()));
  std::map<std::pair<int32_t, int32_t>, int32_t> edge_face;
  for (int32_t f = 0; f < mesh.num_faces(); ++f) {
    if (!evaluator.has_limit_surface(f)) continue;
    const auto fv = mesh.face(f);
    for (size_t i = 0; i < fv.size(); ++i) {
      const int32_t a = fv[i], b = fv[(i + 1) % fv.size()];
      const auto [it, inserted] = edge_face.emplace(std::pair{std::min(a, b), std::max(a, b)}, f);
      if (!inserted) pieces.unite(f, it->second);
    }
  }
  std::map<int32_t, int32_t> piece_of_component;  // a surface piece seen per part
  for (int32_t f = 0; f < mesh.num_faces(); ++f) {
    if (!evaluator.has_limit_surface(f)) continue;
    const int32_t component = component_of[static_cast<size_t>(mesh.face(f)[0])];
    const auto [it, inserted] = piece_of_component.emplace(component, pieces.find(f));
    if (!inserted && it->second != pieces.find(f)) {
      fail(ErrorCode::kUnprocessable,
           "the limit surface of one part of the mesh falls apart into pieces (faces " + std::to_string(it->second) +
               " and " + std::to_string(f) +
               " are on different pieces) that share control points only through faces without a limit surface "
               "(boundary \"none\"): the pieces could move against each other without strain. Add faces that join "
               "them, or make them separate parts");
    }
  }
}

}  // namespace softshell::engine::internal
