// The bounded back-substitution (SmootherOptions::solve_budget_mb, bayestree/partial_solve.h):
// an update solves what it re-eliminated or folded into and, past the budget, defers the rest;
// once the backlog is solved (solveDeferred, or the budgets of later updates) the estimate is the
// one the unbounded smoother gives. Deterministic: the budget counts entries read, not time.

#include <algorithm>
#include <cmath>
#include <random>
#include <stdexcept>
#include <vector>

#include <gtest/gtest.h>

#include "arbor_slam/bayestree/incremental_smoother.h"
#include "arbor_slam/core/se2.h"
#include "arbor_slam/core/se3.h"
#include "arbor_slam/tests/random_walks.h"

namespace arbor {
namespace {

using testing::randomWalk;

// α = 0 (every clique below a solved one is solved again) and no relinearisation: the
// unbounded smoother's Δ is then the exact solution of the Bayes tree's system, and both
// smoothers, fed the same poses, hold the same system.
SmootherOptions linearOptions(double budget_mb) {
  SmootherOptions o;
  o.threads = 1;
  o.wildfire_threshold = 0;
  o.relinearize_threshold_translation = 1e9;
  o.relinearize_threshold_rotation = 1e9;
  o.solve_budget_mb = budget_mb;
  return o;
}

template <class G>
double largestDifference(const std::vector<G>& a, const std::vector<G>& b) {
  double d = 0;
  for (size_t v = 0; v < a.size(); ++v) d = std::max(d, a[v].between(b[v]).Log().norm());
  return d;
}

// Feeds the walk into both smoothers, each pose with its odometry and then each loop closure as
// an update of its own (folded in, or re-eliminating its top), new poses at the truth. Calls
// `check(unbounded, bounded, budgeted stats)` after every update.
template <class G, class Check>
void feedBoth(const std::vector<std::vector<RelativePoseEdge<G>>>& by_pose,
              const std::vector<G>& truth, IncrementalSmoother<G>* a, IncrementalSmoother<G>* b,
              Check check) {
  for (IncrementalSmoother<G>* s : {a, b}) s->addFixedPose(truth[0]);
  for (size_t k = 1; k < by_pose.size(); ++k)
    for (size_t e = 0; e < by_pose[k].size(); ++e) {
      for (IncrementalSmoother<G>* s : {a, b}) {
        if (e == 0) s->addPose(truth[k]);
        s->addFactor(by_pose[k][e]);
      }
      a->update();
      check(*a, b, b->update());
    }
}

template <class G>
void expectTheBacklogSolvedGivesTheUnboundedEstimate(unsigned seed) {
  std::vector<G> truth;
  const auto walk = randomWalk<G>(150, 40, seed, &truth);
  IncrementalSmoother<G> a(linearOptions(0)), b(linearOptions(1e-4));  // 1e-4 MB: 12 doubles
  int updates = 0, deferring = 0, solved_later = 0;
  feedBoth(
      walk, truth, &a, &b,
      [&](const IncrementalSmoother<G>& sa, IncrementalSmoother<G>* sb, const UpdateStats& st) {
        ++updates;
        ASSERT_NO_THROW(sb->checkInvariants()) << "update " << updates;
        if (st.cliques_deferred > 0) ++deferring;
        // Every 7th update the backlog is solved: deferred cliques otherwise live through later
        // updates, which remove some of them with their top (their orphans inherit what they had
        // not seen) and fold into others.
        if (updates % 7 != 0) return;
        const std::vector<G> before = sb->estimate();
        const UpdateStats drained = sb->solveDeferred();
        EXPECT_EQ(drained.cliques_deferred, 0);
        ASSERT_NO_THROW(sb->checkInvariants());
        solved_later += drained.cliques_solved;
        const std::vector<G> after = sb->estimate();
        EXPECT_LE(largestDifference(sa.estimate(), after), 1e-9) << "update " << updates;
        // The poses it moved are listed for publishing.
        const std::vector<int>& listed = sb->updatedPoses();
        for (size_t v = 0; v < after.size(); ++v) {
          if (before[v].between(after[v]).Log().norm() == 0) continue;
          EXPECT_TRUE(std::binary_search(listed.begin(), listed.end(), static_cast<int>(v)))
              << "pose " << v << " moved but is not listed";
        }
      });
  EXPECT_GT(updates, 150);
  // The budget did bound the updates: most deferred something, and the backlogs held work.
  EXPECT_GT(deferring, updates / 2);
  EXPECT_GT(solved_later, 0);
}

TEST(SolveBudget, TheBacklogSolvedGivesTheUnboundedEstimate2D) {
  for (unsigned seed : {1u, 2u}) expectTheBacklogSolvedGivesTheUnboundedEstimate<SE2>(seed);
}

TEST(SolveBudget, TheBacklogSolvedGivesTheUnboundedEstimate3D) {
  expectTheBacklogSolvedGivesTheUnboundedEstimate<SE3>(3);
}

// Without solveDeferred: the budgets of quiet updates (odometry only, which move the old poses
// by less than α) work the backlog off, and the estimate is then the unbounded one to the
// wildfire threshold's effect. (With α = 0 every update's own wildfire would take the whole
// budget: a quiet update re-solves the tree below its new pose.)
TEST(SolveBudget, QuietUpdatesWorkTheBacklogOff) {
  std::vector<SE2> truth;
  auto walk = randomWalk<SE2>(260, 50, 4, &truth);
  // The last 60 poses bring odometry only.
  for (size_t k = 200; k < walk.size(); ++k) walk[k].resize(1);
  SmootherOptions unbounded = linearOptions(0), bounded = linearOptions(0.01);
  unbounded.wildfire_threshold = bounded.wildfire_threshold = 0.001;
  IncrementalSmoother<SE2> a(unbounded), b(bounded);
  int most_deferred = 0, last_deferred = -1, updates = 0;
  feedBoth(walk, truth, &a, &b,
           [&](const IncrementalSmoother<SE2>&, IncrementalSmoother<SE2>*, const UpdateStats& st) {
             ++updates;
             most_deferred = std::max(most_deferred, st.cliques_deferred);
             last_deferred = st.cliques_deferred;
           });
  EXPECT_GT(most_deferred, 10);
  EXPECT_EQ(last_deferred, 0);
  EXPECT_LE(largestDifference(a.estimate(), b.estimate()), 0.01);
  EXPECT_EQ(b.solveDeferred().cliques_solved, 0);  // nothing left
}

// With relinearisation and the default α, the budget delays relinearisation checks and leaves
// stale poses between updates, but the final pass reaches the same optimum.
TEST(SolveBudget, TheFinalPassReachesTheUnboundedOptimum) {
  std::vector<SE3> truth;
  const auto walk = randomWalk<SE3>(120, 30, 5, &truth);
  SmootherOptions unbounded;
  unbounded.threads = 1;
  SmootherOptions bounded = unbounded;
  bounded.solve_budget_mb = 0.001;
  IncrementalSmoother<SE3> a(unbounded), b(bounded);
  feedBoth(walk, truth, &a, &b,
           [](const IncrementalSmoother<SE3>&, IncrementalSmoother<SE3>*, const UpdateStats&) {});
  a.relinearizeAll();
  const UpdateStats st = b.relinearizeAll();
  EXPECT_EQ(st.cliques_deferred, 0);
  EXPECT_NEAR(b.objective(), a.objective(), 1e-7 * a.objective());
  EXPECT_LE(largestDifference(a.estimate(), b.estimate()), 1e-4);
}

TEST(SolveBudget, BadOptionsAreRefused) {
  SmootherOptions o;
  o.solve_budget_mb = -1;
  EXPECT_THROW(IncrementalSmoother<SE2>{o}, std::invalid_argument);
  o.solve_budget_mb = std::nan("");
  EXPECT_THROW(IncrementalSmoother<SE2>{o}, std::invalid_argument);
  o.solve_budget_mb = 1;
  o.dogleg = true;
  EXPECT_THROW(IncrementalSmoother<SE2>{o}, std::invalid_argument);
  o.dogleg = false;
  o.full_backsubstitution = true;
  EXPECT_THROW(IncrementalSmoother<SE2>{o}, std::invalid_argument);
}

}  // namespace
}  // namespace arbor
