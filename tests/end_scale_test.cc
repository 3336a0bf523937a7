// finalize()'s own scale (bayestree/online_gnc.h, "the end's scale"): on sphere_bignoise with
// 10% random false closures (shared data) the c² in use at the end comes from innovations at
// arrival, which the false closures and the drift of the moment inflate, and every false closure
// passes it; the leave-one-out innovations at the end re-estimate c² several times lower, and
// the final check drops the false closures, no true one. Its first 600 poses show it in a second.
#include <algorithm>
#include <iostream>
#include <set>
#include <utility>

#include <gtest/gtest.h>

#include "arbor_slam/bayestree/online_gnc.h"
#include "arbor_slam/core/gnc_solver.h"
#include "arbor_slam/core/pose_graph.h"
#include "arbor_slam/io/labels_file.h"
#include "arbor_slam/io/pose_graph_file.h"
#include "arbor_slam/tools/cli/batch_refinement.h"
#include "arbor_slam/tools/cli/online_threshold.h"
#include "arbor_slam/tools/cli/replay_runner.h"
#include "robust_replay_outcome.h"
#include "shared_data.h"

namespace arbor {
namespace {

const char* const kRobust = "robust/sphere_bignoise_vertex3_random_0.1";
const char* const kClean = "sphere_bignoise_vertex3";
constexpr Key kPoses = 600;

// The graph on the poses with ids below kPoses: those poses, and the edges between them.
PoseGraph3 firstPoses(const std::string& name) {
  const PoseGraph3 all = std::get<PoseGraph3>(readPoseGraphFile(testing::datasetPath(name)));
  PoseGraph3 g;
  for (int k = 0; k < all.numPoses() && all.ids[static_cast<size_t>(k)] < kPoses; ++k) {
    g.ids.push_back(all.ids[static_cast<size_t>(k)]);
    g.index.emplace(g.ids.back(), k);
    g.poses.push_back(all.poses[static_cast<size_t>(k)]);
  }
  for (const auto& e : all.edges)
    if (e.i < g.numPoses() && e.j < g.numPoses()) g.edges.push_back(e);
  g.has_initial_estimate = all.has_initial_estimate;
  return g;
}

using Outcome = testing::RobustOutcome;
using testing::replayRobust;

// The planted false closures among those poses, low id first.
std::set<std::pair<Key, Key>> falseClosures() {
  std::set<std::pair<Key, Key>> out;
  const std::string labels = testing::sharedDir() + "/datasets/" + kRobust + ".labels";
  for (const LabelPair& p : readLabelsFile(labels))
    if (p.first < kPoses && p.second < kPoses)
      out.insert({std::min(p.first, p.second), std::max(p.first, p.second)});
  return out;
}

bool present() { return testing::datasetPresent(kRobust) && testing::datasetPresent(kClean); }

// Measured (47c28c6): without it 0 of the 42 false closures are rejected;
// with it 39, and no true one.
TEST(EndScale, DropsTheFalseClosuresTheEntrysScaleLetsIn) {
  if (!present()) GTEST_SKIP() << "shared dataset absent: " << testing::datasetPath(kRobust);
  const PoseGraph3 graph = firstPoses(kRobust), clean = firstPoses(kClean);
  const std::set<std::pair<Key, Key>> is_false = falseClosures();
  ASSERT_GE(is_false.size(), 30U);
  RobustOptions off;
  off.rules_off.add(RobustRule::kEndScale);
  const Outcome without = replayRobust(clean, graph, off);
  const Outcome with = replayRobust(clean, graph, RobustOptions{});
  std::cout << "rejected " << without.rejected.size() << " -> " << with.rejected.size() << " of "
            << is_false.size() << " false, F_clean " << without.F_clean << " -> " << with.F_clean
            << "\n";
  EXPECT_LE(without.rejected.size(), is_false.size() / 10);
  for (const auto& pair : with.rejected)
    EXPECT_TRUE(is_false.count(pair)) << "a true closure " << pair.first << " " << pair.second;
  EXPECT_GE(with.rejected.size(), is_false.size() * 8 / 10);
  EXPECT_GT(with.unconfirmed, without.unconfirmed);
  EXPECT_LT(with.F_clean, 0.9 * without.F_clean);
  // The c² of the last pass: the entry's without the end's scale, several times below it with.
  EXPECT_DOUBLE_EQ(without.c2_end, without.c2);
  EXPECT_LT(with.c2_end, with.c2 / robust_constants::kEndScaleGap);
}

// The end's scale read on the way (robust_constants::kEndScaleGrowth, kEndScaleWork): read again
// as the poses and the updates' work grow, and where it is far below the c² in use the false
// closures come out during the replay, not only in finalize(), so the updates after carry
// less fill. Measured: on the whole file the updates take 28 s against 128 s without.
TEST(EndScale, ReadOnTheWayDropsBeforeTheEnd) {
  if (!present()) GTEST_SKIP() << "shared dataset absent: " << testing::datasetPath(kRobust);
  const PoseGraph3 graph = firstPoses(kRobust), clean = firstPoses(kClean);
  const std::set<std::pair<Key, Key>> is_false = falseClosures();
  auto updatesOnly = [&](bool reading) {
    cli::ReplaySettings settings;
    settings.robust = RobustOptions{};
    if (!reading) settings.robust->rules_off.add(RobustRule::kEndScale);
    settings.batch = false;
    settings.finalize = false;
    return cli::runReplay(graph, settings);
  };
  const cli::ReplayResult<SE3> off = updatesOnly(false), on = updatesOnly(true);
  std::cout << "before finalize(): " << off.online.closures_unconfirmed << " -> "
            << on.online.closures_unconfirmed << " dropped, " << off.online.closures_outlier
            << " -> " << on.online.closures_outlier << " rejected of " << is_false.size()
            << " false\n";
  // Rejected before finalize(): (false, true) closures.
  auto rejected = [&](const cli::ReplayResult<SE3>& r) {
    std::pair<int, int> n{0, 0};
    for (const ClosureReport& c : r.closures) {
      if (c.status != ClosureStatus::kOutlier) continue;
      ++(is_false.count({std::min(c.from, c.to), std::max(c.from, c.to)}) ? n.first : n.second);
    }
    return n;
  };
  const auto [false_off, true_off] = rejected(off);
  const auto [false_on, true_on] = rejected(on);
  std::cout << "rejected before finalize(): false " << false_off << " -> " << false_on << ", true "
            << true_off << " -> " << true_on << "\n";
  EXPECT_EQ(off.online.closures_unconfirmed, 0);
  EXPECT_GE(false_on - false_off, static_cast<int>(is_false.size()) / 4);
  EXPECT_LE(true_on, true_off + 2);
  // And the replay with finalize() ends as well as without the readings.
  RobustOptions no_readings;
  no_readings.rules_off.add(RobustRule::kEndScale);
  const Outcome without = replayRobust(clean, graph, no_readings);
  const Outcome with = replayRobust(clean, graph, RobustOptions{});
  for (const auto& pair : with.rejected)
    EXPECT_TRUE(is_false.count(pair)) << "a true closure " << pair.first << " " << pair.second;
  EXPECT_GE(with.rejected.size(), is_false.size() * 8 / 10);
  EXPECT_LE(with.F_clean, 1.01 * without.F_clean);
}

// The same first poses without false closures: every closure kept either way, and the same
// estimate (the end's scale only tightens the final check, and no inlier is past it).
TEST(EndScale, KeepsEveryClosureOfTheCleanGraph) {
  if (!present()) GTEST_SKIP() << "shared dataset absent: " << testing::datasetPath(kClean);
  const PoseGraph3 clean = firstPoses(kClean);
  RobustOptions off;
  off.rules_off.add(RobustRule::kEndScale);
  const Outcome without = replayRobust(clean, clean, off);
  const Outcome with = replayRobust(clean, clean, RobustOptions{});
  EXPECT_TRUE(with.rejected.empty());
  EXPECT_EQ(with.unconfirmed, 0);
  EXPECT_DOUBLE_EQ(with.F_clean, without.F_clean);
  EXPECT_GT(with.c2_end, 0.0);
}

// `arbor batch --robust` (from the online replay, its defaults) takes a held-out closure back
// only within the bound the replay's own end took closures back within: the end's scale where it
// stood (OnlineThreshold::c2_take_back), and so does its certifiable path (certifyInliers). Within
// the c² in use, the batch let back false closures that the end's scale had dropped (the whole
// sphere: eight, F_clean 1.0135 F* against 1.0090); within GNC's c², --solver rtr let back 514
// (1.435 F*, not certified).
TEST(EndScale, TheBatchFromTheReplayTakesBackWithinTheEndsBound) {
  if (!present()) GTEST_SKIP() << "shared dataset absent: " << testing::datasetPath(kRobust);
  const PoseGraph3 robust = firstPoses(kRobust);
  std::vector<SE3> poses;
  const cli::OnlineBatch b = cli::solveGncFromReplay(robust, GncOptions{}, EdgeChoices{},
                                                     /*online_threshold=*/true, &poses);
  std::cout << "c2 in use " << b.online.c2_in_use << ", take back within " << b.online.c2_take_back
            << "; held out " << b.known_outliers << ", taken back " << b.readmitted << "\n";
  EXPECT_LT(b.online.c2_take_back, b.online.c2_in_use);
  std::set<std::pair<Key, Key>> rejected;
  for (size_t k = 0; k < robust.edges.size(); ++k)
    if (!b.gnc.inlier[k]) {
      const auto& e = robust.edges[k];
      const Key a = robust.ids[static_cast<size_t>(e.i)], c = robust.ids[static_cast<size_t>(e.j)];
      rejected.insert({std::min(a, c), std::max(a, c)});
    }
  const auto planted = falseClosures();
  int hits = 0;
  for (const auto& p : rejected) hits += planted.count(p) ? 1 : 0;
  std::cout << "rejected " << rejected.size() << ", " << hits << " of the " << planted.size()
            << " planted\n";
  // Measured: 40 of 42 held out and none taken back; within the c² in use all 40 came back.
  EXPECT_EQ(b.readmitted, 0);
  EXPECT_EQ(hits, static_cast<int>(rejected.size()));  // no true closure
  EXPECT_GE(hits, 36);

  // The certifiable path (--solver rtr) takes back at its certified optimum within the same bound.
  // Within GNC's c² (twice the c² in use, 95,831 here) it took all 40 back and the inlier problem
  // was no longer certified.
  GncResult gnc = b.gnc;
  const CertifiedInliers c =
      certifyInliers(robust, &gnc, &poses, RtrOptions{}, /*max_passes=*/5, b.online.c2_take_back);
  EXPECT_EQ(c.readmitted, 0);
  EXPECT_TRUE(c.rtr.certified);
}

// The replay's own final robust batch (`arbor replay --robust --batch lm --reseed`) starts from
// the finalized smoother's classification as `arbor batch --robust` starts from the replay's
// (tools/refine/gnc_from_online.h): the closures it rejected are held out, and none comes back
// beyond its end's bound. GNC at the c² in use with every closure free took all 40 planted ones
// back here, won by Σρ at that c² and was reseeded (on the whole sphere: 1.179 F* over the clean
// edges, against 1.009).
TEST(EndScale, TheReplaysFinalRobustBatchKeepsOutWhatTheEndDropped) {
  if (!present()) GTEST_SKIP() << "shared dataset absent: " << testing::datasetPath(kRobust);
  const PoseGraph3 robust = firstPoses(kRobust), clean = firstPoses(kClean);
  cli::ReplaySettings settings;
  settings.robust = RobustOptions{};
  cli::BatchLoopSettings loop;
  loop.solver = refine::BatchSolver::kLevenbergMarquardt;
  loop.reseed = true;
  loop.synchronous = true;
  const cli::LoopResult<SE3> r = cli::runReplayWithBatches(robust, settings, loop);
  ASSERT_FALSE(r.batches.empty());
  const refine::BatchRun& last = r.batches.back();
  ASSERT_TRUE(last.final_run);
  int rejected = 0;
  for (const ClosureReport& c : r.replay.closures) rejected += c.status == ClosureStatus::kOutlier;
  std::cout << "the replay rejected " << rejected << ", its final batch " << last.rejected << " ("
            << last.winner << ")\n";
  EXPECT_GE(rejected, 36);
  EXPECT_GE(last.rejected, rejected);
  // Whichever estimate won, it is as good on the clean edges as the replay's own.
  const Outcome online = replayRobust(clean, robust, RobustOptions{});
  EXPECT_LE(objective(clean, r.replay.poses), online.F_clean * 1.001);
}

}  // namespace
}  // namespace arbor
