// The swap of asynchronous relinearisation (bayestree/relinearization_swap.h), on hand-built
// bases: a job's result as a base, and the rebase — Θ of poses moved since, the factors added
// since requeued with their weights now, reweightings taken in or out of the structure, the
// poses new to the base's tree and the neighbours they touch — and a catch-up's unattached
// poses held fixed.
#include <vector>

#include <gtest/gtest.h>
#include <Eigen/Core>

#include "arbor_slam/bayestree/relinearization_swap.h"
#include "arbor_slam/core/relative_pose_factor.h"
#include "arbor_slam/core/se2.h"

namespace arbor {
namespace {

using bayestree::Rebased;
using bayestree::SinceSnapshot;
using bayestree::SwapBase;
using bayestree::SwapSource;

Factor<SE2> edge(int i, int j, double weight = 1) {
  Factor<SE2> f = RelativePoseEdge<SE2>::make(i, j, SE2(1, 0, 0.1), Eigen::Matrix3d::Identity());
  f.setInlierWeight(weight);
  return f;
}

double distance(const SE2& a, const SE2& b) { return a.between(b).Log().norm(); }

// The smoother as it is at the swap: `n` poses, pose 0 fixed, the factors given.
struct Source {
  std::vector<SE2> theta;
  std::vector<char> fixed;
  bayestree::LinearizedFactors<SE2> factors;
  std::vector<Factor<SE2>> queued;
  std::vector<int> to_relinearize;
  SinceSnapshot since;
  Source(int n, const std::vector<Factor<SE2>>& fs) {
    for (int v = 0; v < n; ++v) {
      theta.push_back(SE2(v, 0.1 * v, 0.05 * v));
      fixed.push_back(v == 0);
      factors.addVariable();
    }
    for (const Factor<SE2>& f : fs) factors.add(f);
  }
  SwapSource<SE2> view(bool with_queued) const {
    return {theta, fixed, factors, with_queued ? &queued : nullptr, to_relinearize, since};
  }
};

// A base of the first `n` poses and the factors given, at Θ = 2 × the source's translation.
SwapBase<SE2> baseOf(int n, const std::vector<Factor<SE2>>& fs, std::vector<char> fixed) {
  SwapBase<SE2> b;
  b.n = n;
  b.f = static_cast<int>(fs.size());
  b.fixed = std::move(fixed);
  for (int v = 0; v < n; ++v) {
    b.theta.push_back(SE2(2 * v, 0.2 * v, 0.05 * v));
    b.tree.addVariable();
    b.factors.addVariable();
    b.solve.addVariable();
    b.delta.push_back(SE2::Tangent::Zero());
  }
  for (const Factor<SE2>& f : fs) b.factors.add(f);
  return b;
}

TEST(RelinearizationSwap, AJobsResultIsABaseOfItsSnapshot) {
  bayestree::RelinearizationSnapshot<SE2> snap;
  snap.theta = {SE2(0, 0, 0), SE2(1, 0, 0), SE2(2, 0, 0)};
  snap.fixed = {1, 0, 0};
  snap.factors = {edge(0, 1), edge(1, 2)};
  snap.relinearized = {2};
  snap.theta_before = {SE2(2.5, 0, 0)};
  bayestree::RelinearizedTree<SE2> job;
  job.delta.assign(3, SE2::Tangent::Zero());
  SwapBase<SE2> one = bayestree::baseOfJob(bayestree::RelinearizationSnapshot<SE2>(snap),
                                           bayestree::RelinearizedTree<SE2>(job));
  EXPECT_EQ(one.n, 3);
  EXPECT_EQ(one.f, 2);
  EXPECT_FALSE(one.all_relinearized);
  EXPECT_EQ(one.relinearized, std::vector<int>{2});
  EXPECT_EQ(distance(one.theta[2], SE2(2, 0, 0)), 0);
  EXPECT_EQ(distance(one.theta_before[0], SE2(2.5, 0, 0)), 0);
  // Several iterations: every pose stepped; Θ before is the smoother's at the snapshot.
  job.iterations = 2;
  job.theta = {SE2(0, 0, 0), SE2(1.1, 0, 0), SE2(2.1, 0, 0)};
  SwapBase<SE2> more = bayestree::baseOfJob(std::move(snap), std::move(job));
  EXPECT_TRUE(more.all_relinearized);
  EXPECT_EQ(distance(more.theta[1], SE2(1.1, 0, 0)), 0);
  ASSERT_EQ(more.theta_before.size(), 3u);
  EXPECT_EQ(distance(more.theta_before[1], SE2(1, 0, 0)), 0);
  EXPECT_EQ(distance(more.theta_before[2], SE2(2.5, 0, 0)), 0);
}

TEST(RelinearizationSwap, MovedPosesMoveAlikeAndNewPosesKeepTheirValues) {
  const std::vector<Factor<SE2>> old = {edge(0, 1), edge(1, 2)};
  Source src(4, {edge(0, 1), edge(1, 2), edge(2, 3)});
  SwapBase<SE2> base = baseOf(3, old, {1, 0, 0});
  base.relinearized = {2};
  base.theta_before = {SE2(1.5, 0.3, 0)};  // the smoother's θ_2 when the base started
  const SE2 theta2 = base.theta[2];
  src.since.moved = {2, 1, 2};  // repeats allowed
  const Rebased<SE2> r = bayestree::rebase(std::move(base), src.view(false));
  ASSERT_EQ(r.theta.size(), 4u);
  EXPECT_EQ(distance(r.theta[1], src.theta[1]), 0);  // not relinearised: the smoother's
  const SE2 moved = src.theta[2].compose(SE2(1.5, 0.3, 0).inverse()).compose(theta2);
  EXPECT_LT(distance(r.theta[2], moved), 1e-12);
  EXPECT_EQ(distance(r.theta[3], src.theta[3]), 0);
  EXPECT_EQ(distance(r.theta[0], SE2(0, 0, 0)), 0);  // untouched: the base's
  // The moved poses' factors are relinearised, their keys touched (not the fixed pose 0).
  EXPECT_EQ(r.to_relinearize, (std::vector<int>{0, 1, 1}));
  EXPECT_EQ(r.touch, (std::vector<int>{1, 1, 2, 1, 2}));
  EXPECT_EQ(r.new_vars, std::vector<int>{3});
  EXPECT_EQ(r.tree.clique_of.size(), 4u);
  EXPECT_EQ(r.factors.var_factors.size(), 4u);
  EXPECT_EQ(r.delta.size(), 4u);
}

TEST(RelinearizationSwap, FactorsAddedSinceAreRequeuedWithTheirWeightsNow) {
  const std::vector<Factor<SE2>> old = {edge(0, 1), edge(1, 2)};
  Source src(4, {edge(0, 1), edge(1, 2), edge(2, 3, 0.5)});
  src.queued = {edge(1, 3)};
  src.to_relinearize = {1, 2};  // 2 is not in the base: it is requeued anyway
  const Rebased<SE2> without = bayestree::rebase(baseOf(3, old, {1, 0, 0}), src.view(false));
  ASSERT_EQ(without.queued.size(), 1u);
  EXPECT_EQ(without.queued[0].key(1), 3);
  EXPECT_EQ(without.queued[0].inlierWeight(), 0.5);
  EXPECT_EQ(without.to_relinearize, std::vector<int>{1});
  const Rebased<SE2> with = bayestree::rebase(baseOf(3, old, {1, 0, 0}), src.view(true));
  ASSERT_EQ(with.queued.size(), 2u);
  EXPECT_EQ(with.queued[1].key(0), 1);
}

TEST(RelinearizationSwap, ReweightingsTakeFactorsInAndOutOfTheStructure) {
  const std::vector<Factor<SE2>> old = {edge(0, 1), edge(1, 2), edge(0, 2, 0)};
  Source src(3, {edge(0, 1), edge(1, 2, 0), edge(0, 2, 1)});
  src.since.reweighted = {1, 2, 1};
  const Rebased<SE2> r = bayestree::rebase(baseOf(3, old, {1, 0, 0}), src.view(false));
  EXPECT_FALSE(r.factors.attached[1]);  // to 0: out, its keys re-eliminated
  EXPECT_EQ(r.factors.factors[1].inlierWeight(), 0);
  EXPECT_EQ(r.readmitted, std::vector<int>{2});  // from 0: enters the next pass anew
  EXPECT_FALSE(r.factors.attached[2]);
  EXPECT_EQ(r.touch, (std::vector<int>{1, 2}));
  EXPECT_TRUE(r.to_relinearize.empty());
}

TEST(RelinearizationSwap, PosesNewToTheBasesTreeTouchTheirNeighbours) {
  // Pose 2 was not in the base's tree (held fixed there); pose 3 came since.
  const std::vector<Factor<SE2>> old = {edge(0, 1), edge(1, 2)};
  Source src(4, {edge(0, 1), edge(1, 2), edge(2, 3)});
  const Rebased<SE2> r = bayestree::rebase(baseOf(3, old, {1, 0, 1}), src.view(false));
  EXPECT_EQ(r.new_vars, (std::vector<int>{2, 3}));
  EXPECT_EQ(r.touch, std::vector<int>{1});
}

TEST(RelinearizationSwap, ACatchUpHoldsPosesWithoutFactorsFixed) {
  const std::vector<Factor<SE2>> old = {edge(0, 1)};
  Source src(5, {edge(0, 1), edge(1, 2), edge(2, 3, 0)});
  Rebased<SE2> r = bayestree::rebase(baseOf(2, old, {1, 0}), src.view(false));
  ASSERT_EQ(r.new_vars, (std::vector<int>{2, 3, 4}));
  // 2 has a factor requeued; 3 only one of weight 0; 4 none.
  EXPECT_EQ(bayestree::holdUnattached(&r), (std::vector<int>{3, 4}));
  EXPECT_EQ(r.new_vars, std::vector<int>{2});
}

}  // namespace
}  // namespace arbor
