// Gauss-Legendre rules on [0, 1]: exact to degree 2n - 1 (and not beyond), and a clear refusal
// of a size there is no rule for.
#include <cmath>
#include <stdexcept>

#include <gtest/gtest.h>

#include "softshell/gauss_legendre.h"

namespace softshell {
namespace {

double integrate_monomial(const GaussRule& rule, int degree) {
  double sum = 0.0;
  for (size_t i = 0; i < rule.points.size(); ++i) sum += rule.weights[i] * std::pow(rule.points[i], degree);
  return sum;
}

TEST(GaussLegendre, IntegratesPolynomialsUpToDegreeTwoNMinusOne) {
  for (int n = 1; n <= kMaxGaussPoints; ++n) {
    const GaussRule& rule = gauss_legendre(n);
    ASSERT_EQ(rule.points.size(), static_cast<size_t>(n));
    for (size_t i = 0; i < rule.points.size(); ++i) {
      EXPECT_GT(rule.points[i], 0.0);
      EXPECT_LT(rule.points[i], 1.0);
      EXPECT_GT(rule.weights[i], 0.0);
      if (i > 0) {
        EXPECT_GT(rule.points[i], rule.points[i - 1]) << "ascending";
      }
    }
    for (int degree = 0; degree <= 2 * n - 1; ++degree) {
      EXPECT_NEAR(integrate_monomial(rule, degree), 1.0 / (degree + 1), 1e-14) << n << " points, x^" << degree;
    }
    // Degree 2n is where the rule stops being exact, by (n!)^4 / ((2n + 1) ((2n)!)^2) for x^2n on
    // [0, 1] (visible in double precision up to n = 10).
    if (n <= 10) {
      double expected = 1.0 / (2 * n + 1);  // times ((n!)^2 / (2n)!)^2
      for (int k = 1; k <= n; ++k) expected *= static_cast<double>(k * k) / ((n + k) * (n + k));
      EXPECT_NEAR(1.0 / (2 * n + 1) - integrate_monomial(rule, 2 * n), expected, 1e-3 * expected + 1e-16) << n;
    }
  }
}

TEST(GaussLegendre, IsSymmetricAboutTheMidpoint) {
  const GaussRule& rule = gauss_legendre(7);
  for (size_t i = 0; i < rule.points.size(); ++i) {
    EXPECT_NEAR(rule.points[i] + rule.points[rule.points.size() - 1 - i], 1.0, 1e-15);
    EXPECT_NEAR(rule.weights[i], rule.weights[rule.points.size() - 1 - i], 1e-15);
  }
}

TEST(GaussLegendre, RefusesSizesWithoutARule) {
  EXPECT_THROW(gauss_legendre(0), std::out_of_range);
  EXPECT_THROW(gauss_legendre(kMaxGaussPoints + 1), std::out_of_range);
  try {
    gauss_legendre(-3);
  } catch (const std::out_of_range& e) {
    EXPECT_NE(std::string(e.what()).find("1..16"), std::string::npos) << e.what();
  }
}

}  // namespace
}  // namespace softshell
