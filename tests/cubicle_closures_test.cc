// cubicle.g2o (shared data, read with its indefinite Ω repaired, docs/files.md) is not a clean
// file: ten of its loop closures disagree with the rest of the graph. Seven form a group,
// 4298–4316 to 5667–5704, whose yaw is 0.14–0.74 rad off at the plain optimum they pull towards
// (s up to 177 against χ²₆'s 0.99 quantile 16.8); three more, 2550–2552 to 3705–3708, are 0.42 m
// off (s 17–18). The robust replay at Ω's word (NoiseScale::kGiven) rejects exactly these ten
// and ends at the optimum of the graph without them, whose F is a quarter below the full graph's:
// ten of 16,869 edges carry over a quarter of the optimum's F. So issue 14's clean-data goal (F
// within 0.1% of the plain replay's) cannot hold here for a replay that rejects false closures:
// F over every edge, the ten included, ends above the plain replay's (docs/benchmarks.md,
// "Robust replay").
#include <algorithm>
#include <iostream>
#include <set>
#include <utility>

#include <gtest/gtest.h>

#include "arbor_slam/bayestree/online_gnc.h"
#include "arbor_slam/core/batch_solver.h"
#include "arbor_slam/core/pose_graph.h"
#include "arbor_slam/io/pose_graph_file.h"
#include "arbor_slam/tools/cli/replay_runner.h"
#include "shared_data.h"

namespace arbor {
namespace {

const char* const kCubicle = "cubicle";

const std::set<std::pair<Key, Key>> kTen = {
    {2550, 3705}, {2552, 3706}, {2552, 3708},  // 0.42 m off
    {4298, 5703}, {4298, 5704}, {4301, 5699}, {4304, 5697},
    {4305, 5696}, {4306, 5685}, {4316, 5667},  // one group, the yaw off
};

PoseGraph3 loadRepaired() {
  ReadOptions read;
  read.information = InformationPolicy::kRepair;
  return std::get<PoseGraph3>(readPoseGraphFile(testing::datasetPath(kCubicle), read));
}

PoseGraph3 without(const PoseGraph3& graph, const std::set<std::pair<Key, Key>>& pairs) {
  PoseGraph3 out = graph;
  out.edges.clear();
  for (const auto& e : graph.edges) {
    const Key a = graph.ids[static_cast<size_t>(e.i)], b = graph.ids[static_cast<size_t>(e.j)];
    if (pairs.count({std::min(a, b), std::max(a, b)}) == 0) out.edges.push_back(e);
  }
  return out;
}

TEST(CubicleClosures, AtOmegasWordTheReplayRejectsTheTenAndEndsAtTheOptimumWithoutThem) {
  if (!testing::datasetPresent(kCubicle))
    GTEST_SKIP() << "shared dataset absent: " << testing::datasetPath(kCubicle);
  const PoseGraph3 graph = loadRepaired();

  cli::ReplaySettings plain;
  plain.batch = false;
  const double F_plain = objective(graph, cli::runReplay(graph, plain).poses);

  cli::ReplaySettings robust = plain;
  RobustOptions given;
  given.scale = NoiseScale::kGiven;
  robust.robust = given;
  const cli::ReplayResult<SE3> r = cli::runReplay(graph, robust);
  std::set<std::pair<Key, Key>> rejected;
  for (const ClosureReport& c : r.closures)
    if (c.status == ClosureStatus::kOutlier)
      rejected.insert({std::min(c.from, c.to), std::max(c.from, c.to)});
  EXPECT_EQ(rejected, kTen);

  // The optimum without them, by LM from the robust replay's estimate (RTR certifies the same F,
  // 2024.39, docs/benchmarks.md).
  const PoseGraph3 kept = without(graph, kTen);
  ASSERT_EQ(kept.numEdges() + 10, graph.numEdges());
  std::vector<SE3> poses = r.poses;
  const BatchSummary lm = solveBatch(kept, &poses);
  const double F_kept = objective(kept, r.poses);
  std::cout << "F plain " << F_plain << "; robust over every edge " << objective(graph, r.poses)
            << ", over the kept " << F_kept << "; LM without the ten " << lm.F_final << "\n";
  EXPECT_NEAR(F_kept, lm.F_final, 1e-6 * lm.F_final);
  EXPECT_LT(lm.F_final, 0.75 * F_plain);
  EXPECT_GT(objective(graph, r.poses), 1.01 * F_plain);
}

}  // namespace
}  // namespace arbor
