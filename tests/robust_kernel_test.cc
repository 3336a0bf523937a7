// Robust kernels (core/robust_kernel.h): ρ, w = ρ′ and w′ against central differences, the
// quadratic limit w → 1 for small s, TLS's 0/1 weights, the GNC surrogates' μ limits, the χ²
// threshold; Factor's kernel accessors and its √w-scaled linearisation.
#include <cmath>
#include <limits>
#include <stdexcept>

#include <gtest/gtest.h>

#include "arbor_slam/core/factor.h"
#include "arbor_slam/core/robust_kernel.h"

namespace arbor {
namespace {

constexpr double kInf = std::numeric_limits<double>::infinity();

std::vector<RobustKernel> everyKernel(double c2) {
  return {RobustKernel::none(),
          RobustKernel::huber(c2),
          RobustKernel::cauchy(c2),
          RobustKernel::gemanMcClure(c2),
          RobustKernel::gemanMcClure(c2, 20.0),
          RobustKernel::tls(c2),
          RobustKernel::tls(c2, 0.05),
          RobustKernel::tls(c2, 3.0)};
}

TEST(RobustKernel, WeightIsTheDerivativeOfRhoAndDerivativeOfWeight) {
  const double c2 = 7.8;
  for (const RobustKernel& k : everyKernel(c2)) {
    SCOPED_TRACE(toString(k.kind) + " mu " + std::to_string(k.mu));
    for (double s : {0.01, 0.7, 3.0, 7.0, 9.5, 20.0, 150.0, 4000.0}) {
      const double h = 1e-6 * std::max(1.0, s);
      // Skip the kinks (Huber at c², TLS at its band edges), where ρ′ jumps or ρ″ does.
      const auto nearKink = [&](double edge) { return std::abs(s - edge) < 10 * h; };
      if (nearKink(c2)) continue;
      if (k.kind == KernelKind::kTruncatedLeastSquares && std::isfinite(k.mu) &&
          (nearKink(k.mu / (k.mu + 1) * c2) || nearKink((k.mu + 1) / k.mu * c2)))
        continue;
      const double drho = (k.rho(s + h) - k.rho(s - h)) / (2 * h);
      EXPECT_NEAR(k.weight(s), drho, 1e-6 * std::max(1.0, std::abs(drho))) << "s " << s;
      const double dw = (k.weight(s + h) - k.weight(s - h)) / (2 * h);
      EXPECT_NEAR(k.derivative(s), dw, 1e-5 * std::max(1e-3, std::abs(dw))) << "s " << s;
      EXPECT_GE(k.weight(s), 0.0);
      EXPECT_LE(k.weight(s), 1.0);
    }
  }
}

TEST(RobustKernel, QuadraticNearZero) {
  for (const RobustKernel& k : everyKernel(5.0)) {
    SCOPED_TRACE(toString(k.kind));
    EXPECT_EQ(k.rho(0.0), 0.0);
    EXPECT_NEAR(k.weight(1e-9), 1.0, 1e-8);
    EXPECT_NEAR(k.rho(1e-6), 1e-6, 1e-12);
  }
  // Huber and TLS are exactly quadratic below c² (TLS at μ = ∞).
  EXPECT_EQ(RobustKernel::huber(5.0).weight(4.9), 1.0);
  EXPECT_EQ(RobustKernel::huber(5.0).rho(4.9), 4.9);
  EXPECT_EQ(RobustKernel::tls(5.0).rho(4.9), 4.9);
}

TEST(RobustKernel, TruncatedLeastSquaresHasBinaryWeights) {
  const RobustKernel k = RobustKernel::tls(4.0);
  EXPECT_EQ(k.weight(3.999), 1.0);
  EXPECT_EQ(k.weight(4.001), 0.0);
  EXPECT_EQ(k.rho(1e6), 4.0);
  EXPECT_TRUE(k.atKernel());
  // A finite μ has a transition band [μ/(μ+1) c², (μ+1)/μ c²] with weights strictly inside.
  const RobustKernel g = RobustKernel::tls(4.0, 1.0);
  EXPECT_EQ(g.weight(1.99), 1.0);
  EXPECT_EQ(g.weight(8.01), 0.0);
  EXPECT_GT(g.weight(4.0), 0.0);
  EXPECT_LT(g.weight(4.0), 1.0);
  EXPECT_FALSE(g.atKernel());
}

// At the kernel itself a factor is an inlier iff s ≤ c²: its weight is then at least inlierCut.
TEST(RobustKernel, InlierCutIsTheWeightAtTheThreshold) {
  const double c2 = 7.8;
  EXPECT_EQ(RobustKernel::gemanMcClure(c2).inlierCut(), 0.25);
  EXPECT_EQ(RobustKernel::gemanMcClure(c2, 50.0).inlierCut(), 0.25);  // the kernel's, not μ's
  EXPECT_EQ(RobustKernel::cauchy(c2).inlierCut(), 0.5);
  EXPECT_EQ(RobustKernel::huber(c2).inlierCut(), 1.0);
  EXPECT_EQ(RobustKernel::tls(c2).inlierCut(), 0.5);
  EXPECT_EQ(RobustKernel::tls(c2, 2.0).inlierCut(), 0.5);
  EXPECT_EQ(RobustKernel::none().inlierCut(), 0.5);
  for (const RobustKernel& k : {RobustKernel::gemanMcClure(c2), RobustKernel::cauchy(c2),
                                RobustKernel::huber(c2), RobustKernel::tls(c2)}) {
    SCOPED_TRACE(toString(k.kind));
    for (double f : {0.0, 0.2, 0.41, 0.5, 0.9, 0.999, 1.0, 1.001, 1.5, 4.0, 100.0})
      EXPECT_EQ(k.weight(f * c2) >= k.inlierCut(), f <= 1.0) << "s = " << f << " c²";
  }
}

TEST(RobustKernel, GraduatedSurrogatesReachTheirLimits) {
  const double c2 = 3.0;
  // TLS: μ → ∞ is min(s, c²); μ → 0 weighs every finite residual (the convex end).
  const RobustKernel tls_big = RobustKernel::tls(c2, 1e9), tls_small = RobustKernel::tls(c2, 1e-6);
  for (double s : {0.5, 2.9, 3.1, 40.0}) {
    EXPECT_NEAR(tls_big.rho(s), std::min(s, c2), 1e-3) << s;
    EXPECT_GT(tls_small.weight(s), 0.0) << s;
  }
  EXPECT_NEAR(tls_small.weight(40.0), std::sqrt(c2 * 1e-6 / 40.0), 1e-6);
  // GM: μ → ∞ is least squares, μ = 1 is Geman–McClure c² s / (c² + s).
  const RobustKernel gm_big = RobustKernel::gemanMcClure(c2, 1e9);
  const RobustKernel gm = RobustKernel::gemanMcClure(c2);
  for (double s : {0.5, 3.0, 40.0}) {
    EXPECT_NEAR(gm_big.rho(s), s, 1e-6 * s) << s;
    EXPECT_NEAR(gm_big.weight(s), 1.0, 1e-6) << s;
    EXPECT_DOUBLE_EQ(gm.rho(s), c2 * s / (c2 + s)) << s;
  }
  // The schedule: TLS μ grows by the factor, GM's shrinks to 1 and stops there.
  EXPECT_DOUBLE_EQ(RobustKernel::tls(c2, 2.0).nextMu(1.4), 2.8);
  EXPECT_DOUBLE_EQ(RobustKernel::gemanMcClure(c2, 1.2).nextMu(1.4), 1.0);
  EXPECT_TRUE(RobustKernel::gemanMcClure(c2, 1.2).nextMu() == 1.0);
  // μ₀: TLS's makes the largest residual sit on the band's upper edge; GM's is 2 s_max / c².
  const double s_max = 500.0;
  const double mu0 = RobustKernel::tls(c2).initialMu(s_max);
  EXPECT_NEAR((mu0 + 1) / mu0 * c2, 2.0 * s_max, 1e-9 * s_max);
  EXPECT_EQ(RobustKernel::tls(c2).initialMu(1.0), kInf);
  EXPECT_DOUBLE_EQ(RobustKernel::gemanMcClure(c2).initialMu(s_max), 2.0 * s_max / c2);
}

TEST(RobustKernel, ChiSquareThresholdAndNames) {
  EXPECT_NEAR(chiSquareThreshold(0.95, 1), 3.841459, 1e-5);
  EXPECT_NEAR(chiSquareThreshold(0.95, 3), 7.814728, 1e-5);
  EXPECT_NEAR(chiSquareThreshold(0.99, 6), 16.811894, 1e-5);
  EXPECT_THROW(chiSquareThreshold(1.0, 3), std::invalid_argument);
  EXPECT_THROW(chiSquareThreshold(0.9, 0), std::invalid_argument);
  for (KernelKind k : {KernelKind::kNone, KernelKind::kHuber, KernelKind::kCauchy,
                       KernelKind::kGemanMcClure, KernelKind::kTruncatedLeastSquares})
    EXPECT_EQ(parseKernelKind(toString(k)), k);
  EXPECT_THROW(parseKernelKind("welsch"), std::invalid_argument);
  EXPECT_NE(RobustKernel::tls(0.0).problem(), "");
  EXPECT_NE(RobustKernel::tls(2.0, -1.0).problem(), "");
  EXPECT_EQ(RobustKernel::cauchy(2.0).problem(), "");
}

TEST(RobustKernel, FactorCarriesKernelAndScalesItsLinearization) {
  const Edge2 e = Edge2::make(0, 1, SE2(1.0, 0.2, 0.1),
                              (Eigen::Matrix3d() << 20, 1, 0, 1, 30, 2, 0, 2, 100).finished());
  const std::vector<SE2> x = {SE2(0, 0, 0), SE2(1.5, -0.4, 0.6)};
  Factor2 f(e);
  EXPECT_TRUE(f.kernel().isNone());
  EXPECT_EQ(f.inlierWeight(), 1.0);
  const double s = f.cost(x);
  EXPECT_EQ(f.robustCost(x), s);
  EXPECT_EQ(f.kernelWeight(x), 1.0);
  Factor2::Linearization plain, weighted;
  f.linearize(x, &plain);
  f.linearizeWeighted(x, &weighted);  // weight 1: exactly the plain one
  EXPECT_EQ(plain.r, weighted.r);
  EXPECT_EQ(plain.A[0], weighted.A[0]);
  EXPECT_EQ(plain.A[1], weighted.A[1]);

  f.setKernel(RobustKernel::cauchy(2.0));
  EXPECT_EQ(f.cost(x), s);  // cost() stays eᵀΩe
  EXPECT_DOUBLE_EQ(f.robustCost(x), 2.0 * std::log1p(s / 2.0));
  const double w = f.kernelWeight(x);
  EXPECT_DOUBLE_EQ(w, 1.0 / (1.0 + s / 2.0));
  f.setInlierWeight(w);
  f.linearizeWeighted(x, &weighted);
  EXPECT_NEAR(weighted.r.squaredNorm(), w * plain.r.squaredNorm(), 1e-12 * s);
  EXPECT_TRUE(weighted.A[0].isApprox(std::sqrt(w) * plain.A[0]));
  EXPECT_TRUE(weighted.A[1].isApprox(std::sqrt(w) * plain.A[1]));
}

}  // namespace
}  // namespace arbor
