// Disowned at the end (RobustOptions::end_rejected_partners; bayestree/online_gnc.h, "disowned
// at the end"): finalize() drops an unbacked inlier whose partners, the closures that agreed
// with it (P) on arrival, have all been rejected since, past the c² in use itself rather than
// past the margin over it that heavy-tailed true closures need.
#include <iostream>
#include <utility>

#include <gtest/gtest.h>

#include "arbor_slam/bayestree/online_gnc.h"
#include "arbor_slam/core/pose_graph.h"
#include "planted_false_closures.h"
#include "robust_replay_outcome.h"

namespace arbor {
namespace {

// `arbor generate manhattan --poses 3000 --seed 7`, then `arbor generate outliers --outliers 0.5
// --outlier-policy group --seed 7`. The group (9..18, 1303..1312) shares one false transform,
// and for (12, 1306) it happens to lie within 0.48 m and 2° of the truth: its m₋ is 1.08·c²,
// inside the end's margin (1.25). The nine others of its group are rejected, and they are all
// the closures that agreed with it on arrival.
TEST(Disowned, TheLastOfAFalseGroupIsDroppedPastTheThresholdItself) {
  const testing::PlantedGraph<SE2> p = testing::manhattanWithFalseGroups(3000, 7, 0.5);
  ASSERT_EQ(p.is_false.count({12, 1306}), 1U);
  const double F_star = testing::plainReplayF(p.clean);
  const testing::RobustOutcome at_defaults = testing::replayRobust(p.clean, p.graph, {});
  RobustOptions off;
  off.end_rejected_partners = 0;
  const testing::RobustOutcome without = testing::replayRobust(p.clean, p.graph, off);
  std::cout << p.is_false.size()
            << " false closures; F_clean / F*: " << at_defaults.F_clean / F_star << " with "
            << at_defaults.rejected.size() << " rejected (" << at_defaults.disowned
            << " disowned); without the rule " << without.F_clean / F_star << " with "
            << without.rejected.size() << " rejected\n";
  EXPECT_EQ(at_defaults.rejected, p.is_false);
  EXPECT_EQ(at_defaults.disowned, 1);
  EXPECT_LT(at_defaults.F_clean, 1.001 * F_star);
  EXPECT_EQ(without.rejected.count({12, 1306}), 0U);
  EXPECT_EQ(without.disowned, 0);
  EXPECT_GT(without.F_clean, 1.005 * F_star);
}

}  // namespace
}  // namespace arbor
