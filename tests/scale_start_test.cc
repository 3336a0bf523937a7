// Where σ̂²'s fixed point starts once there is an estimate (RobustRule::kScaleStart;
// bayestree/online_gnc.h, "the noise scale"). Groups of false closures agree with each other
// (P), so their innovations join the corroborated set as true runs do; where they become most
// of it, the set's untruncated median lies among them, and a fixed point started there stays
// there. Started at most at the last σ̂², it stays with the true closures that put it there.
#include <cmath>
#include <iostream>
#include <random>
#include <vector>

#include <gtest/gtest.h>

#include "arbor_slam/bayestree/online_gnc.h"
#include "arbor_slam/core/pose_graph.h"
#include "arbor_slam/core/robust_kernel.h"
#include "planted_false_closures.h"
#include "robust_replay_outcome.h"

namespace arbor {
namespace {

// 300 innovations of true closures (σ² = 1, χ²_3) and 400 of false ones, 10³–10^3.5: from the
// untruncated median the fixed point lands among the false ones; capped at the true scale it
// stays there.
TEST(ScaleStart, StartCapKeepsTheFixedPointBelowAFalseMajority) {
  const int dof = 3;
  const double c2 = chiSquareThreshold(0.99, dof);
  std::mt19937 rng(7);
  std::chi_squared_distribution<double> chi2(dof);
  std::uniform_real_distribution<double> far(3.0, 3.5);
  std::vector<double> m;
  for (int k = 0; k < 300; ++k) m.push_back(chi2(rng));
  for (int k = 0; k < 400; ++k) m.push_back(std::pow(10.0, far(rng)));
  const RobustOptions o;
  const NoiseScaleCuts cuts(dof, c2, scaleOptions(o));
  const NoiseScaleEstimate from_median =
      estimateNoiseScale(m, cuts, scaleOptions(o), /*from_median=*/true);
  const NoiseScaleEstimate capped =
      estimateNoiseScale(m, cuts, scaleOptions(o), true, /*start_cap=*/1.2);
  std::cout << "σ̂² from the median " << from_median.sigma2 << ", started at most at 1.2 "
            << capped.sigma2 << "\n";
  EXPECT_GT(from_median.sigma2, 100.0);
  EXPECT_TRUE(capped.estimated);
  EXPECT_NEAR(capped.sigma2, 1.0, 0.25);
  // Above the median the cap changes nothing.
  EXPECT_EQ(estimateNoiseScale(m, cuts, scaleOptions(o), true, 1e9).sigma2, from_median.sigma2);
}

// `arbor generate manhattan --poses 1000 --seed 3`, then `arbor generate outliers --outliers 0.5
// --outlier-policy group --seed 3`: by the 200th corroborated innovation the false groups are
// most of the set. Started from its median each time, σ̂² goes from 1.25 to thousands and every
// closure is accepted; started at most at the last σ̂², the replay ends at F* with exactly the
// false closures rejected.
TEST(ScaleStart, ManhattanWithFiftyPercentGroupFalseClosures) {
  const testing::PlantedGraph<SE2> p = testing::manhattanWithFalseGroups(1000, 3, 0.5);
  const double F_star = testing::plainReplayF(p.clean);
  const testing::RobustOutcome at_defaults = testing::replayRobust(p.clean, p.graph, {});
  RobustOptions from_median;
  from_median.rules_off.add(RobustRule::kScaleStart);
  const testing::RobustOutcome median = testing::replayRobust(p.clean, p.graph, from_median);
  std::cout << p.is_false.size()
            << " false closures; F_clean / F*: " << at_defaults.F_clean / F_star << " with "
            << at_defaults.rejected.size() << " rejected (c² " << at_defaults.c2
            << "); from the median each time " << median.F_clean / F_star << " with "
            << median.rejected.size() << " rejected (c² " << median.c2 << ")\n";
  ASSERT_GT(p.is_false.size(), 100U);
  EXPECT_EQ(at_defaults.rejected, p.is_false);
  EXPECT_LT(at_defaults.F_clean, 1.01 * F_star);
  EXPECT_GT(median.F_clean, 2 * F_star);
}

}  // namespace
}  // namespace arbor
