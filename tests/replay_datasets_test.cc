// Edge-by-edge replay of the shared datasets through the incremental smoother (as
// `arbor replay` does): on every dataset marked replay_target=yes in reference/optimum.tsv the
// final estimate is within 1% of F*; on the others the replay still runs to the end without
// an abort (GTSAM's iSAM2 throws IndeterminantLinearSystemException on M3500b/c).
#include <gtest/gtest.h>

#include "arbor_slam/io/pose_graph_file.h"
#include "arbor_slam/tests/shared_data.h"
#include "arbor_slam/tools/cli/replay_runner.h"

namespace arbor {
namespace {

class ReplayOnDataset : public ::testing::TestWithParam<std::string> {};

TEST_P(ReplayOnDataset, EndsWithinOnePercentOfOptimum) {
  const std::string name = GetParam();
  const auto table = testing::optimumTable();
  if (!testing::datasetPresent(name) || !table.count(name)) {
    GTEST_SKIP() << "shared dataset or reference absent: " << testing::datasetPath(name);
  }
  const auto& ref = table.at(name);
  AnyPoseGraph any = readPoseGraphFile(testing::datasetPath(name));
  std::visit(
      [&](const auto& graph) {
        cli::ReplaySettings settings;
        settings.batch = false;
        const auto r = cli::runReplay(graph, settings);
        EXPECT_EQ(static_cast<int>(r.rows.size()), graph.numEdges());
        EXPECT_EQ(r.rejected, 0);
        EXPECT_EQ(r.pending, 0);
        EXPECT_NEAR(r.F_final, objective(graph, r.poses), 1e-9 * r.F_final);
        EXPECT_LE(r.F_final, r.F_incremental * (1 + 1e-9));
        // Where F* is a certified or LM-confirmed optimum (up to LM's 1e-5 stopping rule), no
        // estimate can be clearly below it. (M3500c's F* is only the best seen: we beat it.)
        if (ref.certified || ref.lm_reaches) {
          EXPECT_GT(r.F_final, ref.F_star * (1 - 1e-3));
        }
        if (ref.replay_target) {
          EXPECT_LT((r.F_final - ref.F_star) / ref.F_star, 0.01)
              << name << ": F_final " << r.F_final << " vs F* " << ref.F_star;
        }
      },
      any);
}

// The 2D sets and the small 3D ones; the large 3D sets (torus3D, sphere, cubicle) take a minute
// or more each and are measured by `arbor bench replay` instead (see docs/benchmarks.md).
INSTANTIATE_TEST_SUITE_P(Shared, ReplayOnDataset,
                         ::testing::Values("tinyGrid3D", "smallGrid3D", "MIT", "intel",
                                           "parking-garage", "M3500", "M3500a", "M3500b", "M3500c",
                                           "manhattan"),
                         [](const auto& info) { return testing::testName(info.param); });

}  // namespace
}  // namespace arbor
