// Tests of the online layer (bayestree/online_smoother.h): external ids, duplicate edges, edges
// between unknown poses (new components) and their joins, out-of-order edges, rejected input.
#include <algorithm>
#include <cmath>
#include <optional>
#include <random>
#include <vector>

#include <gtest/gtest.h>

#include "arbor_slam/bayestree/online_smoother.h"

namespace arbor {
namespace {

const Eigen::Matrix3d kI3 = Eigen::Matrix3d::Identity();

TEST(OnlineSmoother, FirstPoseIsTheFixedGauge) {
  OnlineSmootherOptions<SE2> o;
  o.gauge = SE2(5, -1, 0.3);
  OnlineSmoother<SE2> s(o);
  EXPECT_EQ(s.addEdge(100, 101, SE2(1, 0, 0), kI3).status, EdgeStatus::kAccepted);
  s.update();
  ASSERT_TRUE(s.hasPose(100));
  ASSERT_TRUE(s.hasPose(101));
  EXPECT_TRUE(s.smoother().isFixed(0));
  EXPECT_NEAR(s.estimate(100).x(), 5, 1e-12);
  const SE2 expected = o.gauge.compose(SE2(1, 0, 0));
  EXPECT_NEAR(s.estimate(101).localCoordinates(expected).norm(), 0, 1e-9);
  EXPECT_THROW(s.estimate(7), std::out_of_range);
}

// setInitialGuess (iSAM2's new Θ): a pose an edge creates starts at its guess, not at the pose
// the edge comes from composed with the measurement; a new component's first pose too; a guess
// for a pose that exists, or not finite, is refused; a guess is used once.
TEST(OnlineSmoother, InitialGuessIsWhereACreatedPoseStarts) {
  OnlineSmoother<SE2> s;
  EXPECT_TRUE(s.setInitialGuess(10, SE2(3, 4, 0.5)));
  EXPECT_TRUE(s.setInitialGuess(11, SE2(4, 4, 0.5)));
  EXPECT_EQ(s.addEdge(10, 11, SE2(1.5, 0, 0), kI3).status, EdgeStatus::kAccepted);
  // Before the update the estimate is the start: the guesses, not 10 ∘ z.
  EXPECT_NEAR(s.estimate(10).localCoordinates(SE2(3, 4, 0.5)).norm(), 0, 1e-12);
  EXPECT_NEAR(s.estimate(11).localCoordinates(SE2(4, 4, 0.5)).norm(), 0, 1e-12);
  EXPECT_FALSE(s.setInitialGuess(11, SE2(9, 9, 0)));  // exists
  EXPECT_FALSE(s.setInitialGuess(12, SE2(std::nan(""), 0, 0)));
  s.update();
  // 10 is the fixed gauge pose; 11 moves onto the measurement from its guess.
  EXPECT_NEAR(s.estimate(10).localCoordinates(SE2(3, 4, 0.5)).norm(), 0, 1e-12);
  EXPECT_NEAR(s.estimate(11).localCoordinates(SE2(3, 4, 0.5).compose(SE2(1.5, 0, 0))).norm(), 0,
              1e-6);
  // Without a guess: odometry.
  EXPECT_EQ(s.addEdge(11, 13, SE2(1, 0, 0), kI3).status, EdgeStatus::kAccepted);
  EXPECT_NEAR(s.estimate(13).localCoordinates(s.estimate(11).compose(SE2(1, 0, 0))).norm(), 0,
              1e-12);
}

TEST(OnlineSmoother, DuplicatesAreReportedNotAdded) {
  OnlineSmoother<SE2> s;
  EXPECT_EQ(s.addEdge(1, 2, SE2(1, 0, 0), kI3).status, EdgeStatus::kAccepted);
  s.update();
  const EdgeResult dup = s.addEdge(1, 2, SE2(1, 0, 0), kI3);
  EXPECT_EQ(dup.status, EdgeStatus::kDuplicate);
  EXPECT_FALSE(dup.reason.empty());
  // Same ids but another measurement or Ω: a genuine second measurement.
  EXPECT_EQ(s.addEdge(1, 2, SE2(1.2, 0, 0), kI3).status, EdgeStatus::kAccepted);
  EXPECT_EQ(s.addEdge(1, 2, SE2(1, 0, 0), 2 * kI3).status, EdgeStatus::kAccepted);
  s.update();
  EXPECT_EQ(s.smoother().numFactors(), 3);
  EXPECT_EQ(s.stats().edges_duplicate, 1);
  EXPECT_EQ(s.stats().edges_accepted, 3);
  // Weighted mean of 1 (w 1), 1.2 (w 1), 1 (w 2): 1.05.
  EXPECT_NEAR(s.estimate(2).x(), 1.05, 1e-6);
}

TEST(OnlineSmoother, EdgesBetweenUnknownPosesStartAComponent) {
  OnlineSmoother<SE2> s;
  EXPECT_EQ(s.addEdge(0, 1, SE2(1, 0, 0), kI3).status, EdgeStatus::kAccepted);
  // 10–11 and 11–12: no end known. They start a second component, anchored at 10 and estimated
  // at once in a frame of its own.
  EXPECT_EQ(s.addEdge(10, 11, SE2(1, 0, 0), kI3).status, EdgeStatus::kAccepted);
  EXPECT_EQ(s.addEdge(12, 11, SE2(-1, 0, 0), kI3).status, EdgeStatus::kAccepted);
  EXPECT_EQ(s.addEdge(12, 11, SE2(-1, 0, 0), kI3).status, EdgeStatus::kDuplicate);
  EXPECT_EQ(s.stats().edges_pending, 0);
  EXPECT_EQ(s.stats().components, 2);
  s.update();
  s.smoother().checkInvariants();
  ASSERT_TRUE(s.hasPose(10));
  ASSERT_TRUE(s.hasPose(12));
  EXPECT_EQ(s.anchorOf(12), std::optional<Key>(10));
  EXPECT_NE(s.componentOf(0), s.componentOf(12));
  EXPECT_NEAR(s.estimate(11).x(), 1, 1e-9);  // in its own frame: 10 at the origin
  EXPECT_NEAR(s.estimate(12).x(), 2, 1e-9);
  // 1 → 10 joins them: the younger moves into the older's frame, its anchor is released.
  EXPECT_EQ(s.addEdge(1, 10, SE2(1, 0, M_PI / 2), kI3).status, EdgeStatus::kAccepted);
  s.update();
  s.smoother().checkInvariants();
  EXPECT_EQ(s.stats().components, 1);
  EXPECT_EQ(s.stats().joins, 1);
  EXPECT_EQ(s.componentOf(0), s.componentOf(12));
  EXPECT_EQ(s.anchorOf(12), std::optional<Key>(0));
  EXPECT_TRUE(s.smoother().isFixed(0));
  EXPECT_FALSE(s.smoother().isFixed(2));  // dense index of 10: released
  EXPECT_NEAR(s.estimate(0).x(), 0, 1e-12);
  EXPECT_NEAR(s.estimate(10).x(), 2, 1e-9);
  EXPECT_NEAR(s.estimate(11).y(), 1, 1e-9);
  EXPECT_NEAR(s.estimate(12).y(), 2, 1e-9);
  EXPECT_EQ(s.smoother().numFactors(), 4);
  EXPECT_EQ(s.estimates().size(), 5u);
}

TEST(OnlineSmoother, LongChainStartedAsAComponentJoinsInOneUpdate) {
  OnlineSmoother<SE2> s;
  const int N = 20000;
  EXPECT_EQ(s.addEdge(0, 1, SE2(1, 0, 0), kI3).status, EdgeStatus::kAccepted);
  s.update();
  // N−1 → N starts a component; each earlier pose extends it backwards.
  for (int k = N - 1; k >= 2; --k)
    ASSERT_EQ(s.addEdge(k, k + 1, SE2(1, 0, 0), kI3).status, EdgeStatus::kAccepted);
  EXPECT_EQ(s.stats().components, 2);
  s.update();
  EXPECT_NEAR(s.estimate(N).x() - s.estimate(2).x(), N - 2, 1e-6);
  EXPECT_EQ(s.addEdge(1, 2, SE2(1, 0, 0), kI3).status, EdgeStatus::kAccepted);
  EXPECT_EQ(s.stats().poses, N + 1);
  s.update();
  s.smoother().checkInvariants();
  EXPECT_EQ(s.stats().components, 1);
  EXPECT_NEAR(s.estimate(N).x(), N, 1e-6);
  EXPECT_LT(s.smoother().objective(), 1e-12);
}

TEST(OnlineSmoother, RejectsBadEdges) {
  OnlineSmoother<SE2> s;
  EXPECT_EQ(s.addEdge(3, 3, SE2(), kI3).status, EdgeStatus::kRejected);
  EXPECT_EQ(s.addEdge(3, 4, SE2(std::nan(""), 0, 0), kI3).status, EdgeStatus::kRejected);
  Eigen::Matrix3d nan_info = kI3;
  nan_info(1, 2) = std::nan("");
  EXPECT_EQ(s.addEdge(3, 4, SE2(), nan_info).status, EdgeStatus::kRejected);
  Eigen::Matrix3d indefinite = kI3;
  indefinite(2, 2) = -1;
  const EdgeResult r = s.addEdge(3, 4, SE2(), indefinite);
  EXPECT_EQ(r.status, EdgeStatus::kRejected);
  EXPECT_NE(r.reason.find("information"), std::string::npos) << r.reason;
  EXPECT_EQ(s.stats().edges_rejected, 4);
  EXPECT_EQ(s.stats().poses, 0);
  EXPECT_EQ(s.addEdge(3, 4, SE2(), kI3).status, EdgeStatus::kAccepted);
  // Finite values so large that F would overflow are refused, and what was accepted stays.
  const EdgeResult far = s.addEdge(4, 5, SE2(-1e308, 0, 0), kI3);
  EXPECT_EQ(far.status, EdgeStatus::kRejected);
  EXPECT_NE(far.reason.find("bad measurement: translation component of magnitude 1e+308"),
            std::string::npos)
      << far.reason;
  const EdgeResult heavy = s.addEdge(4, 5, SE2(1, 0, 0), 1e31 * kI3);
  EXPECT_EQ(heavy.status, EdgeStatus::kRejected);
  EXPECT_NE(heavy.reason.find("bad information: has an entry of magnitude 1e+31"),
            std::string::npos)
      << heavy.reason;
  EXPECT_EQ(s.stats().edges_rejected, 6);
  s.update();
  EXPECT_EQ(s.stats().poses, 2);
  EXPECT_TRUE(s.estimate(4).translation().allFinite());
  EXPECT_EQ(s.addEdge(4, 5, SE2(1e14, 0, 0), 1e29 * kI3).status, EdgeStatus::kAccepted);
  s.update();
  EXPECT_NEAR(s.estimate(5).x(), 1e14, 1.0);
}

// Exact measurements of a random 3D trajectory fed in a shuffled order (out of order, both
// directions, many initially dangling): the estimate recovers the trajectory.
TEST(OnlineSmoother, OutOfOrderExactEdgesRecoverTrajectory3D) {
  std::mt19937 rng(7);
  std::normal_distribution<double> n(0, 1);
  const int N = 60;
  std::vector<SE3> truth(N);
  for (int k = 1; k < N; ++k) {
    SE3::Tangent t;
    t << 1 + 0.1 * n(rng), 0.2 * n(rng), 0.1 * n(rng), 0.1 * n(rng), 0.1 * n(rng), 0.3 * n(rng);
    truth[k] = truth[k - 1].compose(SE3::Exp(t));
  }
  struct E {
    int a, b;
  };
  std::vector<E> edges;
  for (int k = 1; k < N; ++k) edges.push_back(k % 3 ? E{k - 1, k} : E{k, k - 1});
  for (int k = 0; k + 7 < N; k += 5) edges.push_back({k + 7, k});
  std::shuffle(edges.begin() + 1, edges.end(), rng);
  OnlineSmoother<SE3> s;
  for (const E& e : edges) {
    const EdgeResult r = s.addEdge(1000 + e.a, 1000 + e.b, truth[e.a].between(truth[e.b]),
                                   Eigen::Matrix<double, 6, 6>::Identity());
    ASSERT_NE(r.status, EdgeStatus::kRejected) << r.reason;
    ASSERT_NE(r.status, EdgeStatus::kDuplicate);
    s.update();
    s.smoother().checkInvariants();
  }
  EXPECT_GT(s.stats().joins, 0);  // shuffled edges started components that joined later
  EXPECT_EQ(s.stats().components, 1);
  EXPECT_EQ(s.stats().poses, N);
  const SE3 origin_inv = truth[edges[0].a].inverse();
  for (int k = 0; k < N; ++k) {
    const SE3 expected = origin_inv.compose(truth[k]);
    EXPECT_LT(s.estimate(1000 + k).localCoordinates(expected).norm(), 1e-6) << k;
  }
  EXPECT_LT(s.smoother().objective(), 1e-10);
}

}  // namespace
}  // namespace arbor
