// tools/refine/gnc_from_online.h: the robust batch from an online smoother's classification.
// On a ring with exact odometry, true loop closures and two gross false ones: the closures the
// smoother rejects stay out unless the refined estimate fits them within the take-back bound;
// a closure it keeps beyond GNC's c² is held at weight 1; bad marks are refused.
#include <cmath>
#include <stdexcept>
#include <utility>
#include <vector>

#include <gtest/gtest.h>

#include "arbor_slam/core/gnc_solver.h"
#include "arbor_slam/core/pose_graph.h"
#include "arbor_slam/core/robust_kernel.h"
#include "arbor_slam/core/se2.h"
#include "arbor_slam/tools/refine/gnc_from_online.h"

namespace arbor::refine {
namespace {

constexpr int kPoses = 40;

struct Ring {
  PoseGraph<SE2> graph;
  int true_closure = -1;           // (0, 10), measured 0.05 m off
  int false_a = -1, false_b = -1;  // gross
};

Ring makeRing() {
  Ring r;
  PoseGraph<SE2>& g = r.graph;
  std::vector<SE2> truth{SE2()};
  for (int k = 1; k < kPoses; ++k) truth.push_back(truth.back().compose(SE2(1, 0, 2 * M_PI / 40)));
  for (int k = 0; k < kPoses; ++k) {
    g.ids.push_back(k);
    g.index[k] = k;
  }
  const Eigen::Matrix3d omega = 100 * Eigen::Matrix3d::Identity();
  auto add = [&](int i, int j, const SE2& z) {
    g.edges.push_back(RelativePoseEdge<SE2>::make(i, j, z, omega));
    return static_cast<int>(g.edges.size()) - 1;
  };
  for (int k = 1; k < kPoses; ++k) add(k - 1, k, truth[k - 1].between(truth[k]));
  r.true_closure = add(0, 10, truth[0].between(truth[10]).compose(SE2(0.05, 0, 0)));
  for (int k = 3; k + 10 < kPoses; k += 3) add(k, k + 10, truth[k].between(truth[k + 10]));
  r.false_a = add(5, 25, SE2(3, -2, 1.0));
  r.false_b = add(12, 33, SE2(-4, 1, -0.7));
  g.poses = truth;  // the smoother's estimate stand-in
  g.has_initial_estimate = true;
  return r;
}

OnlineClassification marks(const Ring& r, std::vector<int> rejected, double take_back) {
  OnlineClassification c;
  c.held_out.assign(r.graph.edges.size(), 0);
  for (int k : rejected) c.held_out[static_cast<size_t>(k)] = 1;
  c.c2 = 2 * chiSquareThreshold(0.99, 3);
  c.c2_take_back = take_back;
  return c;
}

TEST(GncFromOnline, ARejectedClosureComesBackOnlyWithinTheTakeBackBound) {
  const Ring r = makeRing();
  const double c2 = chiSquareThreshold(0.99, 3);
  {
    std::vector<SE2> poses = r.graph.poses;
    const GncFromOnline out = solveGncFromOnline(
        r.graph, GncOptions{}, marks(r, {r.true_closure, r.false_a, r.false_b}, c2), &poses);
    EXPECT_EQ(out.known_outliers, 3);
    EXPECT_EQ(out.readmitted, 1);  // the true closure fits: s ≈ 0.2 at the refined estimate
    EXPECT_EQ(out.kept_beyond, 0);
    EXPECT_TRUE(out.gnc.inlier[static_cast<size_t>(r.true_closure)]);
    EXPECT_FALSE(out.gnc.inlier[static_cast<size_t>(r.false_a)]);
    EXPECT_FALSE(out.gnc.inlier[static_cast<size_t>(r.false_b)]);
    EXPECT_EQ(out.gnc.rejected, 2);
  }
  {  // within a bound below its s it stays out
    std::vector<SE2> poses = r.graph.poses;
    const GncFromOnline out = solveGncFromOnline(
        r.graph, GncOptions{}, marks(r, {r.true_closure, r.false_a, r.false_b}, 0.01), &poses);
    EXPECT_EQ(out.readmitted, 0);
    EXPECT_FALSE(out.gnc.inlier[static_cast<size_t>(r.true_closure)]);
    EXPECT_EQ(out.gnc.rejected, 3);
  }
}

TEST(GncFromOnline, AClosureKeptBeyondTheBoundIsHeldAtWeightOne) {
  const Ring r = makeRing();
  std::vector<SE2> poses = r.graph.poses;
  // The smoother keeps false_b (its end backed it): GNC does not undo that judgement.
  const GncFromOnline out = solveGncFromOnline(
      r.graph, GncOptions{}, marks(r, {r.false_a}, chiSquareThreshold(0.99, 3)), &poses);
  EXPECT_EQ(out.kept_beyond, 1);
  EXPECT_TRUE(out.gnc.trusted[static_cast<size_t>(r.false_b)]);
  EXPECT_TRUE(out.gnc.inlier[static_cast<size_t>(r.false_b)]);
  EXPECT_FALSE(out.gnc.inlier[static_cast<size_t>(r.false_a)]);
  EXPECT_DOUBLE_EQ(out.gnc.threshold, 2 * chiSquareThreshold(0.99, 3));
  // Without the online bound (c2 ≤ 0): GNC at its own c², nothing held, false_b judged.
  std::vector<SE2> again = r.graph.poses;
  OnlineClassification free = marks(r, {r.false_a}, 0);
  free.c2 = 0;
  const GncFromOnline g = solveGncFromOnline(r.graph, GncOptions{}, free, &again);
  EXPECT_EQ(g.kept_beyond, 0);
  EXPECT_FALSE(g.gnc.inlier[static_cast<size_t>(r.false_b)]);
}

TEST(GncFromOnline, RefusesMarksOfTheWrongSizeAndGivesTheBounds) {
  const Ring r = makeRing();
  std::vector<SE2> poses = r.graph.poses;
  OnlineClassification bad;
  bad.held_out.assign(3, 0);
  EXPECT_THROW(solveGncFromOnline(r.graph, GncOptions{}, bad, &poses), std::invalid_argument);
  // Before a finalize() the take-back bound is the c² in use; after it, the end's, capped by it.
  OnlineClassification b = onlineBounds(10, 0, 2);
  EXPECT_DOUBLE_EQ(b.c2, 20);
  EXPECT_DOUBLE_EQ(b.c2_take_back, 10);
  EXPECT_DOUBLE_EQ(onlineBounds(10, 4, 2).c2_take_back, 4);
  EXPECT_DOUBLE_EQ(onlineBounds(10, 40, 2).c2_take_back, 10);
}

}  // namespace
}  // namespace arbor::refine
