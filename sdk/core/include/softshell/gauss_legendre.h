#pragma once
/// \file
/// \brief Gauss-Legendre rules on [0, 1]: the quadrature the engine integrates the shell with,
/// for clients that integrate over the limit surface themselves (areas, loads, moments).

#include <vector>

namespace softshell {

/// Most points per direction a rule has.
inline constexpr int kMaxGaussPoints = 16;

/// The n-point rule on [0, 1]: points ascending, weights summing to 1. Exact for polynomials of
/// degree 2n - 1.
struct GaussRule {
  std::vector<double> points;
  std::vector<double> weights;
};

/// The rule with n points, 1 <= n <= kMaxGaussPoints (computed once, then shared; thread-safe).
/// Throws std::out_of_range for another n.
const GaussRule& gauss_legendre(int n);

/// The same, copied into `points` and `weights`.
void gauss_legendre_01(int n, std::vector<double>& points, std::vector<double>& weights);

}  // namespace softshell
