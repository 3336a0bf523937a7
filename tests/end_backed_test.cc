// Backed at the end (bayestree/online_gnc.h, "backed at the end"): the clean parking garage's
// loop closures have a heavy tail; three true ones (526–646, 644–711, 771–1016) sit at 2.1–2.4
// times the c² in use at the plain replay's estimate, so TLS rejects them and F ends 0.9% above
// the plain replay's. Each has 12–18 settled inliers around it that agree with it (P) at the
// closures' own scale; finalize() takes such closures back within end_backed_margin·c². The
// garage with 10% random false closures (shared data) keeps exactly the true ones.
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

// The backing off, and kept at Ω's word off too (it takes the same closures back: below).
RobustOptions withoutBacking() {
  RobustOptions o;
  o.end_backed_margin = 0;
  o.end_word = false;
  return o;
}

// F over the graph's edges at the plain (non-robust) replay's estimate.
double plainReplayF(const PoseGraph3& clean) {
  cli::ReplaySettings settings;
  settings.batch = false;
  return objective(clean, cli::runReplay(clean, settings).poses);
}

const std::set<std::pair<Key, Key>> kHeavyTail = {{526, 646}, {644, 711}, {771, 1016}};

TEST(EndBacked, KeepsTheCleanGaragesHeavyTail) {
  if (!testing::datasetPresent(kClean))
    GTEST_SKIP() << "shared dataset absent: " << testing::datasetPath(kClean);
  const PoseGraph3 clean = load(kClean);
  const double F_plain = plainReplayF(clean);
  const Outcome without = replayRobust(clean, clean, withoutBacking());
  const Outcome with = replayRobust(clean, clean, RobustOptions{});
  std::cout << "F plain " << F_plain << ", robust " << without.F_clean << " -> " << with.F_clean
            << "; rejected " << without.rejected.size() << " -> " << with.rejected.size() << "\n";
  EXPECT_EQ(without.rejected, kHeavyTail);
  EXPECT_GT(without.F_clean, 1.005 * F_plain);
  EXPECT_TRUE(with.rejected.empty());
  EXPECT_NEAR(with.F_clean, F_plain, 1e-3 * F_plain);  // issue 14: within 0.1%
  // Kept at Ω's word alone keeps them too: their s at the end is within Ω's c².
  RobustOptions word_only = withoutBacking();
  word_only.end_word = true;
  EXPECT_TRUE(replayRobust(clean, clean, word_only).rejected.empty());
}

// `arbor batch --robust --init online --inlier-threshold online`: GNC at twice the replay's c²
// would reject the three again (s 2.1–2.4·c² at the replay's estimate); the batch holds what the
// replay's end kept beyond its c² as trusted, and ends where the replay does.
TEST(EndBacked, TheBatchFromTheReplayKeepsWhatItsEndKept) {
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

// Once taken back they stay: a closure is kept by the c² its re-check flips it at (the c² in
// use), so the rounds settle, and the outcome does not depend on how many are allowed (judged
// by the end's c² instead, the three went out and in every round, and odd limits lost them).
TEST(EndBacked, TheRoundsSettle) {
  if (!testing::datasetPresent(kClean))
    GTEST_SKIP() << "shared dataset absent: " << testing::datasetPath(kClean);
  const PoseGraph3 clean = load(kClean);
  for (int rounds : {3, 4}) {
    RobustOptions o;
    o.finalize_rounds = rounds;
    EXPECT_TRUE(replayRobust(clean, clean, o).rejected.empty()) << rounds << " rounds";
  }
}

TEST(EndBacked, TakesBackOnlyTrueClosuresOfTheRobustGarage) {
  if (!testing::datasetPresent(kRobust) || !testing::datasetPresent(kClean))
    GTEST_SKIP() << "shared dataset absent: " << testing::datasetPath(kRobust);
  const PoseGraph3 graph = load(kRobust), clean = load(kClean);
  std::set<std::pair<Key, Key>> is_false;
  for (const LabelPair& p :
       readLabelsFile(testing::sharedDir() + "/datasets/" + kRobust + ".labels"))
    is_false.insert({std::min(p.first, p.second), std::max(p.first, p.second)});
  ASSERT_GT(is_false.size(), 400U);
  const Outcome without = replayRobust(clean, graph, withoutBacking());
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
