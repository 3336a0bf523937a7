// The noise scale's estimator (bayestree/noise_scale.h) on samples of known scale: true
// closures' innovations drawn from σ² χ²_d, false ones far beyond, as its statistical model
// states. Ω right (σ² = 1), 20–100× cautious (σ² 0.01–0.05) and 20–50× over-confident (σ² 20–50);
// d = 3 (2D) and 6 (3D); 0–30% false closures. What the header promises is checked: σ̂² near σ²
// where it may move the threshold, the refusal to loosen from a few hundred innovations, and the
// bias a heavy tail of true closures leaves.
#include <cmath>
#include <cstdint>
#include <random>
#include <string>
#include <vector>

#include <gtest/gtest.h>

#include "arbor_slam/bayestree/noise_scale.h"
#include "arbor_slam/core/robust_kernel.h"

namespace arbor {
namespace {

struct Draw {
  int n = 100;               ///< innovations
  double sigma2 = 1;         ///< the true closures' scale
  double false_share = 0;    ///< of the n, false closures
  double tail_share = 0;     ///< of the true ones, drawn with tail_factor² times the variance
  double tail_variance = 1;  ///< that factor
};

// Innovations as the model has them: true ones σ²·κ·χ²_d (κ = 1, or tail_variance for a share),
// false ones σ²·χ²_d(0.99)·U with U log-uniform in [30, 3000] (far past any threshold here).
std::vector<double> innovations(const Draw& d, int dof, std::uint64_t seed) {
  std::mt19937_64 rng(seed);
  std::chi_squared_distribution<double> chi2(dof);
  std::uniform_real_distribution<double> unit(0, 1);
  const double q99 = chiSquareThreshold(0.99, dof);
  std::vector<double> m;
  for (int k = 0; k < d.n; ++k) {
    if (unit(rng) < d.false_share) {
      m.push_back(d.sigma2 * q99 * 30 * std::pow(100.0, unit(rng)));
      continue;
    }
    const double kappa = unit(rng) < d.tail_share ? d.tail_variance : 1.0;
    m.push_back(d.sigma2 * kappa * chi2(rng));
  }
  return m;
}

// `from_median`: the fixed points start at the sample's median, as for the corroborated
// innovations the online layer estimates from (few false closures among them).
NoiseScaleEstimate estimate(const std::vector<double>& m, int dof, bool from_median = false) {
  return estimateNoiseScale(m, dof, chiSquareThreshold(0.99, dof), NoiseScaleOptions{},
                            from_median);
}

// Ω right or cautious, up to 30% false closures, 100 innovations: σ̂² within a third of σ² on
// each of twenty draws.
TEST(NoiseScale, RightOrCautiousScaleIsFoundFromAHundredInnovations) {
  for (const int dof : {3, 6})
    for (const double sigma2 : {1.0, 0.05, 0.02, 0.01})
      for (const double false_share : {0.0, 0.1, 0.3})
        for (std::uint64_t seed = 1; seed <= 20; ++seed) {
          Draw d;
          d.sigma2 = sigma2;
          d.false_share = false_share;
          const NoiseScaleEstimate e = estimate(innovations(d, dof, seed), dof);
          ASSERT_TRUE(e.estimated) << "dof " << dof << " σ² " << sigma2 << " seed " << seed;
          EXPECT_GT(e.sigma2, 0.67 * sigma2)
              << "dof " << dof << " σ² " << sigma2 << " false " << false_share << " seed " << seed;
          EXPECT_LT(e.sigma2, 1.5 * sigma2)
              << "dof " << dof << " σ² " << sigma2 << " false " << false_share << " seed " << seed;
        }
}

// Over-confident Ω (σ² 20–50): the estimate loosens Ω only when a quarter of the innovations lie
// within the truncation at σ² = 1 or loosen_min_samples (200) are in. From 120 innovations that
// holds at σ² 20 in 2D (χ²₃ ≤ t/20 for about a third) and never at σ² 50 (Ω at its word: the
// over-confident family's failure, issue 52); from 250, started at their median as the online
// layer starts from its corroborated innovations, σ̂² is found as for the others.
TEST(NoiseScale, OverConfidentScaleIsRefusedBelowTheLooseningRuleAndFoundAbove) {
  for (const int dof : {3, 6})
    for (const double sigma2 : {20.0, 50.0})
      for (std::uint64_t seed = 1; seed <= 10; ++seed) {
        SCOPED_TRACE("dof " + std::to_string(dof) + " σ² " + std::to_string(sigma2) + " seed " +
                     std::to_string(seed));
        Draw d;
        d.sigma2 = sigma2;
        d.false_share = 0.1;
        d.n = 120;
        const NoiseScaleEstimate few = estimate(innovations(d, dof, seed), dof, true);
        EXPECT_EQ(few.estimated, few.share_at_word >= NoiseScaleOptions{}.min_kept_share);
        if (sigma2 == 50.0) {
          EXPECT_FALSE(few.estimated);
        }
        d.n = 250;
        const NoiseScaleEstimate e = estimate(innovations(d, dof, seed), dof, true);
        ASSERT_TRUE(e.estimated);
        EXPECT_GT(e.sigma2, 0.67 * sigma2);
        EXPECT_LT(e.sigma2, 1.5 * sigma2);
      }
}

// A heavy tail of true closures (5% with 36 times the variance, as the vehicle and small-loop
// families draw them): σ̂² stays at the core's scale (the bias the header states), so the
// threshold tail_factor·c²·σ̂² lies below the tail's innovations.
TEST(NoiseScale, AHeavyTailLeavesTheCoresScale) {
  const int dof = 3;
  const double c2 = chiSquareThreshold(0.99, dof);
  int tail_past_threshold = 0;
  for (std::uint64_t seed = 1; seed <= 10; ++seed) {
    Draw d;
    d.sigma2 = 0.02;
    d.tail_share = 0.05;
    d.tail_variance = 36;
    const std::vector<double> m = innovations(d, dof, seed);
    const NoiseScaleEstimate e = estimate(m, dof);
    ASSERT_TRUE(e.estimated);
    EXPECT_LT(e.sigma2, 2.0 * d.sigma2) << "seed " << seed;
    for (const double v : m)
      tail_past_threshold += v > NoiseScaleOptions{}.tail_factor * c2 * e.sigma2;
  }
  EXPECT_GT(tail_past_threshold, 0);
}

TEST(NoiseScale, NoInnovationsNoEstimate) {
  const NoiseScaleEstimate e = estimate({}, 3);
  EXPECT_FALSE(e.estimated);
  EXPECT_EQ(e.sigma2, 1.0);
  EXPECT_FALSE(estimate({0.1, 0.2}, 3).estimated);  // fewer than 3 within the truncation
}

}  // namespace
}  // namespace arbor
