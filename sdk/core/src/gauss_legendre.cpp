#include "softshell/gauss_legendre.h"

#include <array>
#include <cmath>
#include <numbers>
#include <stdexcept>
#include <string>

namespace softshell {
namespace {

// Newton iteration on the roots of the Legendre polynomial P_n from Tricomi's initial guesses;
// exact to round-off for n <= 16.
GaussRule compute(int n) {
  GaussRule rule;
  rule.points.assign(static_cast<size_t>(n), 0.0);
  rule.weights.assign(static_cast<size_t>(n), 0.0);
  for (int i = 0; i < n; ++i) {
    double x = std::cos(std::numbers::pi * (i + 0.75) / (n + 0.5));
    double dp = 1.0;
    for (int iter = 0; iter < 100; ++iter) {
      double p0 = 1.0, p1 = x;
      for (int k = 2; k <= n; ++k) {
        const double p2 = ((2.0 * k - 1.0) * x * p1 - (k - 1.0) * p0) / k;
        p0 = p1;
        p1 = p2;
      }
      dp = n * (x * p1 - p0) / (x * x - 1.0);
      const double dx = p1 / dp;
      x -= dx;
      if (std::abs(dx) < 1e-16) break;
    }
    // [-1, 1] -> [0, 1], ascending; the weight on [0, 1] is half the one on [-1, 1].
    rule.points[static_cast<size_t>(n - 1 - i)] = 0.5 * (x + 1.0);
    rule.weights[static_cast<size_t>(n - 1 - i)] = 1.0 / ((1.0 - x * x) * dp * dp);
  }
  return rule;
}

}  // namespace

const GaussRule& gauss_legendre(int n) {
  if (n < 1 || n > kMaxGaussPoints) {
    throw std::out_of_range("gauss_legendre: " + std::to_string(n) + " points; 1.." +
                            std::to_string(kMaxGaussPoints) + " are available");
  }
  static const std::array<GaussRule, kMaxGaussPoints> rules = [] {
    std::array<GaussRule, kMaxGaussPoints> all;
    for (int k = 1; k <= kMaxGaussPoints; ++k) all[static_cast<size_t>(k - 1)] = compute(k);
    return all;
  }();
  return rules[static_cast<size_t>(n - 1)];
}

void gauss_legendre_01(int n, std::vector<double>& points, std::vector<double>& weights) {
  const GaussRule& rule = gauss_legendre(n);
  points = rule.points;
  weights = rule.weights;
}

}  // namespace softshell
