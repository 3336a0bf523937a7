// The clean parking garage's loop closures have a heavy tail: three true ones (526–646, 644–711,
// 771–1016) sit at 2.1–2.4 times the c² in use at the plain replay's estimate, so TLS rejects
// them and F ends 0.9% above the plain replay's. Their residuals at the final estimate are within
// Ω's own χ² bound, and kept at Ω's word (bayestree/online_gnc.h) takes them back. The garage
// with 10% random false closures (shared data) keeps exactly the true ones.
#include <algorithm>
#include <iostream>
#include <set>
#include <utility>

#include <gtest/gtest.h>

#include "arbor_slam/bayestree/online_gnc.h"
#include "arbor_slam/core/pose_graph.h"
#include "arbor_slam/io/labels_file.h"
#include "arbor_slam/io/pose_graph_file.h"
#include "arbor_slam/tools/cli/online_threshold.h"
#include "arbor_slam/tools/cli/replay_runner.h"
#include "robust_replay_outcome.h"
#include "shared_data.h"

namespace arbor {
namespace {

const char* const kClean = "parking-garage";
const char* const kRobust = "robust/parking-garage_random_0.1";

using Outcome = testing::RobustOutcome;
using testing::replayRobust;

PoseGraph3 load(const std::string& name) {
  return std::get<PoseGraph3>(readPoseGraphFile(testing::datasetPath(name)));
}

// Kept at Ω's word off.
RobustOptions withoutEndWord() {
  RobustOptions o;
  o.rules_off.add(RobustRule::kEndWord);
  return o;
}

// F over the graph's edges at the plain (non-robust) replay's estimate.
double plainReplayF(const PoseGraph3& clean) {
  cli::ReplaySettings settings;
  settings.batch = false;
  return objective(clean, cli::runReplay(clean, settings).poses);
}

const std::set<std::pair<Key, Key>> kHeavyTail = {{526, 646}, {644, 711}, {771, 1016}};

TEST(GarageHeavyTail, KeepsTheCleanGaragesHeavyTail) {
  if (!testing::datasetPresent(kClean))
    GTEST_SKIP() << "shared dataset absent: " << testing::datasetPath(kClean);
  const PoseGraph3 clean = load(kClean);
  const double F_plain = plainReplayF(clean);
  const Outcome without = replayRobust(clean, clean, withoutEndWord());
  const Outcome with = replayRobust(clean, clean, RobustOptions{});
  std::cout << "F plain " << F_plain << ", robust " << without.F_clean << " -> " << with.F_clean
            << "; rejected " << without.rejected.size() << " -> " << with.rejected.size() << "\n";
  EXPECT_EQ(without.rejected, kHeavyTail);
  EXPECT_GT(without.F_clean, 1.005 * F_plain);
  EXPECT_TRUE(with.rejected.empty());
  EXPECT_NEAR(with.F_clean, F_plain, 1e-3 * F_plain);  // issue 14: within 0.1%
}

// `arbor batch --robust --init online --inlier-threshold online`: GNC at twice the replay's c²
// would reject the three again (s 2.1–2.4·c² at the replay's estimate); the batch holds what the
// replay's end kept beyond its c² as trusted, and ends where the replay does.
TEST(GarageHeavyTail, TheBatchFromTheReplayKeepsWhatItsEndKept) {
  if (!testing::datasetPresent(kClean))
    GTEST_SKIP() << "shared dataset absent: " << testing::datasetPath(kClean);
  const PoseGraph3 clean = load(kClean);
  std::vector<SE3> poses;
  const cli::OnlineBatch b = cli::solveGncFromReplay(clean, GncOptions{}, EdgeChoices{},
                                                     /*online_threshold=*/true, &poses);
  EXPECT_EQ(b.kept_beyond, 3);
  EXPECT_EQ(b.known_outliers, 0);
  int rejected = 0;
  for (size_t k = 0; k < b.gnc.inlier.size(); ++k) rejected += b.gnc.inlier[k] ? 0 : 1;
  EXPECT_EQ(rejected, 0);
  const double F_plain = plainReplayF(clean);
  EXPECT_NEAR(objective(clean, poses), F_plain, 1e-3 * F_plain);
}

// The outcome does not depend on how many rounds finalize() is allowed.
TEST(GarageHeavyTail, TheRoundsSettle) {
  if (!testing::datasetPresent(kClean))
    GTEST_SKIP() << "shared dataset absent: " << testing::datasetPath(kClean);
  const PoseGraph3 clean = load(kClean);
  for (int rounds : {3, 4}) {
    RobustOptions o;
    o.finalize_rounds = rounds;
    EXPECT_TRUE(replayRobust(clean, clean, o).rejected.empty()) << rounds << " rounds";
  }
}

TEST(GarageHeavyTail, TakesBackOnlyTrueClosuresOfTheRobustGarage) {
  if (!testing::datasetPresent(kRobust) || !testing::datasetPresent(kClean))
    GTEST_SKIP() << "shared dataset absent: " << testing::datasetPath(kRobust);
  const PoseGraph3 graph = load(kRobust), clean = load(kClean);
  std::set<std::pair<Key, Key>> is_false;
  for (const LabelPair& p :
       readLabelsFile(testing::sharedDir() + "/datasets/" + kRobust + ".labels"))
    is_false.insert({std::min(p.first, p.second), std::max(p.first, p.second)});
  ASSERT_GT(is_false.size(), 400U);
  const Outcome without = replayRobust(clean, graph, withoutEndWord());
  const Outcome with = replayRobust(clean, graph, RobustOptions{});
  std::cout << "rejected " << without.rejected.size() << " -> " << with.rejected.size() << " of "
            << is_false.size() << " false, F_clean " << without.F_clean << " -> " << with.F_clean
            << "\n";
  for (const auto& pair : kHeavyTail) EXPECT_TRUE(without.rejected.count(pair));
  EXPECT_EQ(with.rejected, is_false);
  EXPECT_LT(with.F_clean, without.F_clean);
}

}  // namespace
}  // namespace arbor
