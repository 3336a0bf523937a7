// When the c² in use shrinks by recheck_margin, every settled inlier is checked against it at
// once, not in the round robin's turn (bayestree/online_gnc.h, "a shrinking c²"). Intel with
// 90% group false closures (seed 1; shared data): the first closures are mostly false, the
// first σ̂² (56.8, from their corroborated innovations) lets three groups of them in, and when
// the true closures take σ̂² to 0.018 the round robin reached true closures, bent by the false
// ones, before the false ones, and the replay diverged. With the sweep, and the re-hold of
// what Ω's word rejected (RobustRule::kRehold), it ends at F* with exactly the false
// closures rejected.
#include <algorithm>
#include <cstdint>
#include <iostream>
#include <vector>

#include <gtest/gtest.h>

#include "arbor_slam/bayestree/online_gnc.h"
#include "arbor_slam/bayestree/online_smoother.h"
#include "arbor_slam/core/pose_graph.h"
#include "arbor_slam/io/pose_graph_file.h"
#include "arbor_slam/tools/cli/replay_order.h"
#include "arbor_slam/tools/generator/false_closures.h"
#include "planted_false_closures.h"
#include "robust_replay_outcome.h"
#include "shared_data.h"

namespace arbor {
namespace {

using Planted = testing::PlantedGraph<SE2>;

// `arbor generate intel.g2o --outliers 0.9 --outlier-policy group --seed 1`.
Planted intelWithGroups() {
  sim::OutlierOptions o;
  o.fraction = 0.9;
  o.policy = sim::OutlierPolicy::kGroup;
  o.seed = 1;
  return testing::plantFalseClosures(
      std::get<PoseGraph2>(readPoseGraphFile(testing::datasetPath("intel"))), o);
}

TEST(ShrinkingThreshold, IntelWithNinetyPercentGroupFalseClosures) {
  if (!testing::datasetPresent("intel"))
    GTEST_SKIP() << "shared dataset absent: " << testing::datasetPath("intel");
  const Planted p = intelWithGroups();
  ASSERT_EQ(p.is_false.size(), 706U);
  const double F_star = testing::plainReplayF(p.clean);
  const testing::RobustOutcome at_defaults = testing::replayRobust(p.clean, p.graph, {});
  RobustOptions no_rehold;
  no_rehold.rules_off.add(RobustRule::kRehold);
  const testing::RobustOutcome without = testing::replayRobust(p.clean, p.graph, no_rehold);
  std::cout << "F_clean / F*: " << at_defaults.F_clean / F_star << " with "
            << at_defaults.rejected.size() << " rejected; without the re-hold "
            << without.F_clean / F_star << "\n";
  EXPECT_EQ(at_defaults.rejected, p.is_false);
  EXPECT_LT(at_defaults.F_clean, 1.01 * F_star);
  EXPECT_GT(without.F_clean, 2 * F_star);
}

// The update after the one whose σ̂² took c² below half its peak: every closure that update's
// step left settled at weight 1 was read within recheck_margin·c², and more inliers went back
// to graduation at once than the round robin re-checks in an update.
TEST(ShrinkingThreshold, EveryInlierIsCheckedAtOnce) {
  if (!testing::datasetPresent("intel"))
    GTEST_SKIP() << "shared dataset absent: " << testing::datasetPath("intel");
  const Planted p = intelWithGroups();
  OnlineSmootherOptions<SE2> options;
  options.robust = RobustOptions{};
  options.robust->rechecks_per_update = 4;  // the sweep's count well clear of the round robin's
  const RobustOptions& robust = *options.robust;
  OnlineSmoother2 replay(options);
  std::vector<int> order;
  for (const auto& group : cli::replayGroups(p.graph, false))
    order.insert(order.end(), group.begin(), group.end());
  double peak = 0;
  bool swept = false;
  for (int e : order) {
    const auto& edge = p.graph.edges[static_cast<size_t>(e)];
    ASSERT_EQ(
        replay
            .addEdge(p.graph.ids[static_cast<size_t>(edge.i)],
                     p.graph.ids[static_cast<size_t>(edge.j)], edge.measurement, edge.information)
            .status,
        EdgeStatus::kAccepted);
    const double c2 = replay.gnc()->threshold();  // the edge's innovation is in σ̂² now
    const int regraduated_before = replay.gnc()->counts().regraduated;
    replay.update();
    peak = std::max(peak, c2);
    if (robust_constants::kRecheckMargin * c2 >= peak) continue;
    int settled_inliers = 0;
    for (const ClosureReport& r : replay.closures()) {
      if (r.graduating || r.status != ClosureStatus::kInlier) continue;
      ++settled_inliers;
      EXPECT_LE(r.residual, robust_constants::kRecheckMargin * c2) << r.from << " " << r.to;
    }
    const int regraduated = replay.gnc()->counts().regraduated - regraduated_before;
    std::cout << "c² " << peak << " -> " << c2 << ": " << regraduated
              << " inliers graduated again, " << settled_inliers << " settled inliers left\n";
    EXPECT_GT(regraduated, robust.rechecks_per_update);
    swept = true;
    break;
  }
  EXPECT_TRUE(swept) << "c² never shrank by recheck_margin";
}

}  // namespace
}  // namespace arbor
