// The smoother's side of asynchronous relinearisation (bayestree/relinearization_jobs.h), with a
// stand-in for the smoother's state: when a job and a catch-up are due, how many catch-ups a
// job may chain, what a catch-up's base records of the smoother at its start, and that what
// changed since the snapshot is forgotten when a new one starts or the work is abandoned.
#include <memory>
#include <vector>

#include <gtest/gtest.h>
#include <Eigen/Core>

#include "arbor_slam/bayestree/relinearization_jobs.h"
#include "arbor_slam/core/relative_pose_factor.h"
#include "arbor_slam/core/se2.h"

namespace arbor {
namespace {

using Jobs = bayestree::RelinearizationJobs<SE2, int>;  // the state: a count of passes run

const std::vector<SE2> kTheta = {SE2(0, 0, 0), SE2(1, 0, 0), SE2(2, 0, 0)};

void startCatchUp(Jobs* jobs, bool first_round, int factors, int update) {
  jobs->startCatchUp(
      std::make_unique<int>(0), [](int& passes) { ++passes; }, kTheta, factors, 7, first_round,
      /*synchronous=*/true, update);
}

TEST(RelinearizationJobs, ACatchUpIsDueWhenDoneOrAtTheUpdateAfterItsStart) {
  Jobs jobs;
  EXPECT_FALSE(jobs.pending());
  jobs.since.moved = {1};
  startCatchUp(&jobs, true, 5, 10);
  EXPECT_TRUE(jobs.pending());
  EXPECT_TRUE(jobs.since.moved.empty());  // recorded from the catch-up's start on
  AsyncRelinearizationOptions o;
  EXPECT_TRUE(jobs.catchUpSwapDue(10, o));  // done (it ran on this thread)
  EXPECT_FALSE(jobs.jobSwapDue(10, o));     // no job pending
  o.swap_after_updates = 2;
  EXPECT_FALSE(jobs.catchUpSwapDue(10, o));
  EXPECT_TRUE(jobs.catchUpSwapDue(11, o));
  bayestree::SwapBase<SE2> base;
  const std::unique_ptr<int> state = jobs.takeCatchUp(&base);
  EXPECT_EQ(*state, 1);  // its pass ran
  EXPECT_FALSE(jobs.pending());
  EXPECT_EQ(base.n, 3);
  EXPECT_EQ(base.f, 5);
  EXPECT_TRUE(base.all_relinearized);
  ASSERT_EQ(base.theta_before.size(), 3u);
  EXPECT_EQ(base.theta_before[2].between(kTheta[2]).Log().norm(), 0);
  EXPECT_EQ(jobs.catchUpRelinearized(), 7);
}

TEST(RelinearizationJobs, CatchUpsChainWhileTooManyFactorsArriveUpToTheRounds) {
  Jobs jobs;
  AsyncRelinearizationOptions o;
  o.catch_up_max_factors = 3;
  o.catch_up_max_rounds = 2;
  startCatchUp(&jobs, true, 5, 10);
  EXPECT_FALSE(jobs.catchUpAgain(8, o, true));  // 3 arrived: not more than 3
  EXPECT_TRUE(jobs.catchUpAgain(9, o, true));
  EXPECT_FALSE(jobs.catchUpAgain(9, o, /*allowed=*/false));  // the second core is taken
  bayestree::SwapBase<SE2> base;
  jobs.takeCatchUp(&base);
  startCatchUp(&jobs, false, 9, 11);  // round 2 of 2
  EXPECT_FALSE(jobs.catchUpAgain(100, o, true));
  EXPECT_EQ(jobs.catchUpRelinearized(), 7);  // the job's |M|, kept over the rounds
  o.catch_up_max_factors = 0;                // off
  EXPECT_FALSE(jobs.catchUpAgain(100, o, true));
}

TEST(RelinearizationJobs, AbandonDropsTheWorkAndWhatChangedSince) {
  Jobs jobs;
  startCatchUp(&jobs, true, 5, 10);
  jobs.since.reweighted = {4};
  jobs.abandon();
  EXPECT_FALSE(jobs.pending());
  EXPECT_TRUE(jobs.since.reweighted.empty());
}

TEST(RelinearizationJobs, AJobSnapshotsThetaWithItsMarkedVariablesStepped) {
  Jobs jobs;
  bayestree::RelinearizationSnapshot<SE2> s;
  s.theta = kTheta;
  s.fixed = {1, 0, 0};
  s.relinearized = {2, 1};
  s.update = 20;
  s.nested_dissection_min = 1 << 30;
  const Eigen::Matrix3d I = Eigen::Matrix3d::Identity();
  const std::vector<Factor<SE2>> factors = {RelativePoseEdge<SE2>::make(0, 1, SE2(1, 0, 0), I),
                                            RelativePoseEdge<SE2>::make(1, 2, SE2(1, 0, 0), I),
                                            RelativePoseEdge<SE2>::make(0, 2, SE2(2, 0, 0), I)};
  std::vector<SE2::Tangent> delta(3, SE2::Tangent::Zero());
  delta[1][0] = 0.5;
  jobs.since.released = {2};
  jobs.startJob(std::move(s), factors, /*num_factors=*/2, delta, /*synchronous=*/true);
  EXPECT_TRUE(jobs.pending());
  EXPECT_TRUE(jobs.since.released.empty());
  AsyncRelinearizationOptions o;
  EXPECT_TRUE(jobs.jobSwapDue(20, o));
  o.swap_after_updates = 3;
  EXPECT_FALSE(jobs.jobSwapDue(22, o));
  EXPECT_TRUE(jobs.jobSwapDue(23, o));
  int relinearized = 0;
  const bayestree::SwapBase<SE2> base = jobs.takeJob(&relinearized);
  EXPECT_FALSE(jobs.pending());
  EXPECT_EQ(relinearized, 2);
  EXPECT_EQ(base.n, 3);
  EXPECT_EQ(base.f, 2);  // the factors of the tree only
  EXPECT_EQ(base.relinearized, (std::vector<int>{1, 2}));
  EXPECT_EQ(base.theta_before[0].between(kTheta[1]).Log().norm(), 0);
  EXPECT_LT(base.theta[1].between(kTheta[1].retract(delta[1])).Log().norm(), 1e-15);
  EXPECT_EQ(base.tree.clique_of.size(), 3u);
}

}  // namespace
}  // namespace arbor
