// Closures rejected at Ω's word before σ̂² is first estimated are held again when that estimate
// raises c² many times (RobustRule::kRehold; bayestree/online_gnc.h,
// "warm-up"). A
// generated sphere with Ω 100 times too confident in rotation and 10% random false closures:
// without it the round robin of re-checks takes rejected closures back one at a time on an
// estimate that has none of them, false ones among them, and the replay is wrecked (seed 1:
// F_clean 5·10²⁵ F*); with it the false closures, and only they, are rejected.
#include <algorithm>
#include <iostream>
#include <set>
#include <utility>

#include <gtest/gtest.h>

#include "arbor_slam/bayestree/online_gnc.h"
#include "arbor_slam/core/pose_graph.h"
#include "arbor_slam/tools/generator/false_closures.h"
#include "arbor_slam/tools/generator/graph_generator.h"
#include "planted_false_closures.h"
#include "robust_replay_outcome.h"

namespace arbor {
namespace {

using Planted = testing::PlantedGraph<SE3>;

// 10 rings of 30 poses, rotation noise 0.1 rad, every Ω's rotation block 100 times the truth's.
Planted overconfidentSphere(std::uint64_t seed) {
  sim::SphereOptions o;
  o.rings = 10;
  o.poses_per_ring = 30;
  o.noise = {0.05, 0.1};
  o.seed = seed;
  PoseGraph3 clean = sim::sphereWorld(o).graph;
  for (auto& e : clean.edges) e.information.bottomRightCorner<3, 3>() *= 100.0;
  sim::OutlierOptions outliers;
  outliers.seed = seed;
  return testing::plantFalseClosures(std::move(clean), outliers);
}

using Outcome = testing::RobustOutcome;

Outcome replayRobust(const Planted& p, const RobustOptions& robust) {
  return testing::replayRobust(p.clean, p.graph, robust);
}

TEST(Rehold, RejectedAtOmegasWordAreJudgedAgain) {
  for (std::uint64_t seed : {1, 2, 3}) {
    const Planted p = overconfidentSphere(seed);
    ASSERT_GE(p.is_false.size(), 20U);
    RobustOptions on;  // rehold_growth 4, the default
    RobustOptions off;
    off.rules_off.add(RobustRule::kRehold);
    const Outcome without = replayRobust(p, off);
    const Outcome with = replayRobust(p, on);
    // The clean graph's optimum from the plain replay of it.
    const double F_star = testing::plainReplayF(p.clean);
    std::cout << "seed " << seed << ": rejected " << without.rejected.size() << " -> "
              << with.rejected.size() << " of " << p.is_false.size() << " false, F_clean / F* "
              << without.F_clean / F_star << " -> " << with.F_clean / F_star << "\n";
    EXPECT_EQ(with.rejected, p.is_false) << "seed " << seed;
    EXPECT_LT(with.F_clean, 1.01 * F_star) << "seed " << seed;
    // Seed 1 is wrecked without it (seeds 2 and 3 are not: their estimate came in time).
    if (seed == 1) {
      EXPECT_GT(without.F_clean, 2 * F_star);
    }
  }
}

}  // namespace
}  // namespace arbor
