// `arbor bench growth` (tools/bench/growth.h) on small generated graphs: the slices cover every
// update once, in order of graph size, and each carries the factorisation cost of its prefix.
#include <gtest/gtest.h>

#include <algorithm>
#include <stdexcept>

#include "arbor_slam/tools/bench/growth.h"
#include "arbor_slam/tools/generator/graph_generator.h"

namespace arbor {
namespace {

template <class G>
cli::ReplayResult<G> replayOf(const PoseGraph<G>& graph, bool per_pose) {
  cli::ReplaySettings settings;
  settings.per_pose = per_pose;
  settings.finalize = false;
  settings.batch = false;
  return cli::runReplay(graph, settings);
}

template <class G>
void expectSlicesCoverTheReplay(const PoseGraph<G>& graph, bool per_pose, int slices) {
  const auto replay = replayOf(graph, per_pose);
  const auto out = bench::growthSlices(graph, replay, per_pose, slices);
  ASSERT_EQ(static_cast<int>(out.size()), slices);
  int updates = 0, relin = 0, previous_poses = 0;
  for (const auto& r : replay.rows) relin += r.variables_relinearized > 0 ? 1 : 0;
  int relin_in_slices = 0;
  double largest = 0;
  for (const auto& r : replay.rows) largest = std::max(largest, r.latency_ms);
  double largest_in_slices = 0;
  for (const bench::GrowthSlice& s : out) {
    // The largest update of the slice bounds every figure of it.
    EXPECT_GE(s.max_ms, s.relin_max_ms);
    EXPECT_GE(s.max_ms, s.other_p99_ms);
    largest_in_slices = std::max(largest_in_slices, s.max_ms);
    // The largest update is named by its row: its step, its latency, its kind.
    const auto row =
        std::find_if(replay.rows.begin(), replay.rows.end(),
                     [&](const cli::UpdateRow& r) { return r.step == s.largest_step; });
    ASSERT_NE(row, replay.rows.end());
    EXPECT_EQ(row->latency_ms, s.max_ms);
    EXPECT_EQ(s.largest_kind, bench::updateKind(*row));
    EXPECT_GT(s.poses, previous_poses);
    previous_poses = s.poses;
    updates += s.relin_updates + s.other_updates;
    relin_in_slices += s.relin_updates;
    EXPECT_GT(s.factorization_flops, 0);
    EXPECT_GT(s.block_ms, 0);
    EXPECT_GT(s.cholmod_ms, 0);
    EXPECT_EQ(s.factorization_ms, std::min(s.block_ms, s.cholmod_ms));
    EXPECT_GT(s.linearization_ms, 0);
    EXPECT_GE(s.relin_share, 0);
    EXPECT_LE(s.relin_share, 1);
    if (s.relin_updates > 0) {
      EXPECT_GE(s.relin_max_ms, s.relin_p50_ms);
    }
    if (s.other_updates > 0) {
      EXPECT_GE(s.other_p99_ms, s.other_p50_ms);
    }
  }
  EXPECT_EQ(updates, static_cast<int>(replay.rows.size()));
  EXPECT_EQ(relin_in_slices, relin);
  EXPECT_EQ(largest_in_slices, largest);
  EXPECT_EQ(out.back().poses, graph.numPoses());
  EXPECT_EQ(out.back().edges, graph.numEdges());
  // The whole graph costs more to factor than its first slice.
  EXPECT_GT(out.back().factorization_flops, 2 * out.front().factorization_flops);
}

TEST(BenchGrowth, SlicesCoverEveryUpdateOfASphereOnceInOrderOfSize) {
  sim::SphereOptions options;
  options.rings = 12;
  options.poses_per_ring = 20;
  const auto world = sim::sphereWorld(options);
  expectSlicesCoverTheReplay(world.graph, /*per_pose=*/false, 4);
  expectSlicesCoverTheReplay(world.graph, /*per_pose=*/true, 3);
}

TEST(BenchGrowth, SlicesCoverEveryUpdateOfAManhattanWorld) {
  sim::ManhattanOptions options;
  options.poses = 400;
  const auto world = sim::manhattanWorld(options);
  expectSlicesCoverTheReplay(world.graph, /*per_pose=*/false, 5);
}

TEST(BenchGrowth, NamesAnUpdateByWhatItDid) {
  cli::UpdateRow row;
  EXPECT_EQ(bench::updateKind(row), "other");
  row.cliques_updated = 3;
  EXPECT_EQ(bench::updateKind(row), "fold-in");
  row.cliques_reeliminated = 3;
  EXPECT_EQ(bench::updateKind(row), "top");
  row.variables_relinearized = 5;
  EXPECT_EQ(bench::updateKind(row), "relinearisation");
  row.batch_reeliminations = 1;
  EXPECT_EQ(bench::updateKind(row), "batch");
  row.async_swapped = 1;
  EXPECT_EQ(bench::updateKind(row), "swap");
}

TEST(BenchGrowth, RejectsRowsOfAnotherFeedingAndZeroSlices) {
  sim::SphereOptions options;
  options.rings = 4;
  options.poses_per_ring = 10;
  const auto world = sim::sphereWorld(options);
  const auto per_pose = replayOf(world.graph, /*per_pose=*/true);
  EXPECT_THROW(bench::growthSlices(world.graph, per_pose, /*per_pose=*/false, 2),
               std::invalid_argument);
  EXPECT_THROW(bench::growthSlices(world.graph, per_pose, /*per_pose=*/true, 0),
               std::invalid_argument);
}

}  // namespace
}  // namespace arbor
