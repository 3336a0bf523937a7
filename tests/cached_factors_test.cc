// Cliques without a cached factor (SmootherOptions::cached_factors, docs/design.md "Cliques
// without a cached factor"): a smoother that drops them eliminates the same linear systems, so
// every estimate equals the one that keeps them all, through fold-ins, relinearisations, batch
// re-eliminations and background jobs, while its tree holds fewer doubles. Deterministic
// counts and estimates, no timing.

#include <algorithm>
#include <limits>
#include <stdexcept>
#include <vector>

#include "arbor_slam/bayestree/elimination_plan.h"
#include "arbor_slam/bayestree/incremental_smoother.h"
#include "arbor_slam/bayestree/tree_shape.h"
#include "arbor_slam/tests/random_walks.h"

#include <gtest/gtest.h>

namespace arbor {
namespace {

using testing::randomWalk;
using testing::replayWalk;

SmootherOptions exactOptions() {
  SmootherOptions o;
  o.threads = 1;
  o.wildfire_threshold = 0;  // every clique below a change is solved: exact comparisons
  o.cached_factors.min_tree_doubles = 0;  // these trees are small: drop at any size
  return o;
}

struct DropRun {
  std::vector<double> doubles;  // factorizationDoubles() after each update
  int folded = 0, batches = 0, relinearized = 0;
};

// Replays the walk with `dropping` (some max_ratio) and with every cached factor kept (the same
// options otherwise): the estimates agree after every update, the dropping tree's invariants
// hold after every update, and its tree holds fewer doubles.
template <class G>
DropRun expectDroppingEqualsKeeping(unsigned seed, SmootherOptions dropping) {
  std::vector<G> truth;
  const auto by_pose = randomWalk<G>(300, 60, seed, &truth);
  SmootherOptions keeping = dropping;
  keeping.cached_factors.max_ratio = 0;
  IncrementalSmoother<G> kept(keeping);
  std::vector<std::vector<G>> estimates;
  DropRun keep_run;
  replayWalk(by_pose, &kept, [&](const IncrementalSmoother<G>& s, const UpdateStats&) {
    estimates.push_back(s.estimate());
    keep_run.doubles.push_back(s.factorizationDoubles());
  });
  IncrementalSmoother<G> dropped(dropping);
  DropRun run;
  size_t u = 0;
  replayWalk(by_pose, &dropped, [&](const IncrementalSmoother<G>& s, const UpdateStats& st) {
    ASSERT_NO_THROW(s.checkInvariants()) << "update " << u + 1;
    run.folded += st.cliques_updated > 0 ? 1 : 0;
    run.batches += st.batch_reeliminations;
    run.relinearized += st.variables_relinearized;
    run.doubles.push_back(s.factorizationDoubles());
    const std::vector<G> x = s.estimate();
    for (size_t v = 0; v < x.size(); ++v)
      ASSERT_LT(estimates[u][v].between(x[v]).Log().norm(), 1e-8)
          << "update " << u + 1 << ", pose " << v;
    ++u;
  });
  EXPECT_LT(run.doubles.back(), keep_run.doubles.back());
  EXPECT_LT(dropped.memory().clique_bytes, kept.memory().clique_bytes);
  EXPECT_NEAR(dropped.objective(), kept.objective(), 1e-9 * kept.objective());
  return run;
}

// Ratio 0.5: every clique whose cached factor outweighs half its conditional keeps none, most
// of the tree on these walks. Fold-ins and relinearisations both happen.
TEST(CachedFactors, DroppingEqualsKeepingAfterEveryUpdate2D) {
  SmootherOptions o = exactOptions();
  o.cached_factors.max_ratio = 0.5;
  for (unsigned seed : {31u, 32u}) {
    const DropRun r = expectDroppingEqualsKeeping<SE2>(seed, o);
    EXPECT_GT(r.folded, 0);
    EXPECT_GT(r.relinearized, 0);
  }
}
TEST(CachedFactors, DroppingEqualsKeepingAfterEveryUpdate3D) {
  SmootherOptions o = exactOptions();
  o.cached_factors.max_ratio = 0.5;
  for (unsigned seed : {41u, 42u}) {
    const DropRun r = expectDroppingEqualsKeeping<SE3>(seed, o);
    EXPECT_GT(r.folded, 0);
    EXPECT_GT(r.relinearized, 0);
  }
}

// With the batch switch firing often (whole-graph re-eliminations in fresh orderings) and
// without rank updates (every loop closure re-eliminates its path).
TEST(CachedFactors, DroppingEqualsKeepingWithBatchesAndWithoutRankUpdates) {
  SmootherOptions o = exactOptions();
  o.cached_factors.max_ratio = 1;
  o.batch.top_share = 0.2;
  o.batch.reorder_decay = 1.0;
  EXPECT_GT(expectDroppingEqualsKeeping<SE2>(51, o).batches, 5);
  o.rank_updates = false;
  EXPECT_EQ(expectDroppingEqualsKeeping<SE3>(52, o).folded, 0);
}

// Background relinearisation jobs build their trees with the same rule (the snapshot carries
// it), and the swap folds what came meanwhile into them: still equal, update by update.
TEST(CachedFactors, DroppingEqualsKeepingWithAsyncRelinearization) {
  SmootherOptions o = exactOptions();
  o.batch.top_share = 1;
  o.batch.reorder_decay = 0;
  o.relinearize = RelinearizationMode::kAsync;
  o.async.min_variables = 1;
  o.async.synchronous = true;
  o.async.swap_after_updates = 3;
  o.cached_factors.max_ratio = 0.5;
  expectDroppingEqualsKeeping<SE2>(61, o);
  o.async.catch_up = AsyncCatchUp::kOnSwap;
  expectDroppingEqualsKeeping<SE3>(62, o);
}

// The tree's doubles follow the rule: the fewer cliques keep their cached factor, the fewer
// doubles, and the sum is what checkInvariants recounts (asserted above after every update).
TEST(CachedFactors, LowerRatiosHoldFewerDoubles) {
  std::vector<SE2> truth;
  const auto by_pose = randomWalk<SE2>(300, 60, 71, &truth);
  double previous = 0;
  for (double ratio : {0.0, 8.0, 1.0, 0.25}) {
    SmootherOptions o = exactOptions();
    o.batch.reorder_decay = 0;
    o.cached_factors.max_ratio = ratio;
    IncrementalSmoother2 s(o);
    replayWalk(by_pose, &s, [](const IncrementalSmoother2&, const UpdateStats&) {});
    // A last full re-elimination, so each tree is its ratio's fresh one.
    s.relinearizeAll();
    const double d = s.factorizationDoubles();
    if (previous > 0) {
      EXPECT_LT(d, previous) << "ratio " << ratio;
    }
    previous = d;
  }
}

// By default a small tree keeps every cached factor (CachedFactorOptions::min_tree_doubles):
// the same doubles as at ratio 0 after every update; at min 0 the same walk drops some.
TEST(CachedFactors, SmallTreesKeepEveryCachedFactorByDefault) {
  std::vector<SE3> truth;
  const auto by_pose = randomWalk<SE3>(300, 60, 81, &truth);
  SmootherOptions keep_all;
  keep_all.threads = 1;
  keep_all.cached_factors.max_ratio = 0;
  SmootherOptions defaults;
  defaults.threads = 1;
  SmootherOptions any_size = defaults;
  any_size.cached_factors.min_tree_doubles = 0;
  IncrementalSmoother<SE3> a(keep_all), b(defaults), c(any_size);
  std::vector<double> kept;
  replayWalk(by_pose, &a, [&](const IncrementalSmoother<SE3>& s, const UpdateStats&) {
    kept.push_back(s.factorizationDoubles());
  });
  ASSERT_LT(kept.back(), defaults.cached_factors.min_tree_doubles) << "a small tree";
  size_t u = 0;
  replayWalk(by_pose, &b, [&](const IncrementalSmoother<SE3>& s, const UpdateStats&) {
    EXPECT_EQ(s.factorizationDoubles(), kept[u]) << "update " << u + 1;
    ++u;
  });
  replayWalk(by_pose, &c, [](const IncrementalSmoother<SE3>&, const UpdateStats&) {});
  EXPECT_LT(c.factorizationDoubles(), kept.back());
}

// treeShape (what `arbor bench tree` prints): a ratio only moves doubles from the kept cached
// factors to the dropped ones (at ratios up to 1 some), and the conditionals, flops and cliques
// stay.
TEST(CachedFactors, TreeShapeSplitsTheCachedFactorsByRatio) {
  std::vector<SE2> truth;
  const auto by_pose = randomWalk<SE2>(300, 60, 91, &truth);
  bayestree::RowList rows;
  int n = 0;
  for (size_t k = 1; k < by_pose.size(); ++k)
    for (const auto& e : by_pose[k]) {
      n = std::max(n, e.j);
      if (e.i == 0) continue;  // pose 0 fixed
      rows.add(e.i - 1);
      rows.add(e.j - 1);
      rows.endRow();
    }
  const std::vector<int> group(static_cast<size_t>(n), 0);
  const bayestree::EliminationPlan plan =
      bayestree::planElimination(n, rows, bayestree::constrainedColamd(n, rows, group));
  const bayestree::TreeShape all = bayestree::treeShape<3>(plan, 0);
  EXPECT_EQ(all.dropped_doubles, 0.0);
  EXPECT_EQ(all.cliques_without_cached, 0);
  EXPECT_GT(all.cached_doubles, 0.0);
  for (double ratio : {8.0, 1.0, 0.25}) {
    const bayestree::TreeShape s = bayestree::treeShape<3>(plan, ratio);
    EXPECT_EQ(s.cliques, all.cliques);
    EXPECT_EQ(s.flops, all.flops);
    EXPECT_EQ(s.conditional_doubles, all.conditional_doubles);
    EXPECT_NEAR(s.allKeptDoubles(), all.doubles(), 1e-9 * all.doubles()) << ratio;
    if (ratio <= 1) {
      EXPECT_GT(s.cliques_without_cached, 0) << ratio;
      EXPECT_LT(s.doubles(), all.doubles()) << ratio;
    }
  }
}

TEST(CachedFactors, NegativeOrInfiniteRatioIsRefused) {
  SmootherOptions o;
  o.cached_factors.max_ratio = -1;
  EXPECT_THROW(IncrementalSmoother2 s(o), std::invalid_argument);
  o.cached_factors.max_ratio = std::numeric_limits<double>::infinity();
  EXPECT_THROW(IncrementalSmoother2 s(o), std::invalid_argument);
  o.cached_factors.max_ratio = 4;
  o.cached_factors.min_tree_doubles = -1;
  EXPECT_THROW(IncrementalSmoother2 s(o), std::invalid_argument);
}

}  // namespace
}  // namespace arbor
