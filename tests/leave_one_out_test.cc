// The leave-one-out innovation (bayestree/closure_innovation.h) and what the online GNC does
// with it (bayestree/online_gnc.h, "confirmed at the end"): (L) on the graph with a closure
// equals (E) on the graph without it, where (E) read on the tree that holds the closure is far
// lower; a pose without Σ has no (L); and finalize()'s (L) at kFinalConfirmMargin·c²
// (RobustRule::kFinalConfirm) drops smallGrid3D's isolated false closure.
#include <algorithm>
#include <cmath>
#include <cstdint>
#include <iostream>
#include <set>
#include <vector>

#include <gtest/gtest.h>

#include "arbor_slam/bayestree/closure_innovation.h"
#include "arbor_slam/bayestree/incremental_smoother.h"
#include "arbor_slam/bayestree/online_smoother.h"
#include "arbor_slam/core/pose_graph.h"
#include "arbor_slam/core/robust_kernel.h"
#include "arbor_slam/io/pose_graph_file.h"
#include "arbor_slam/tests/random_graphs.h"
#include "arbor_slam/tools/cli/replay_runner.h"
#include "arbor_slam/tools/generator/false_closures.h"
#include "planted_false_closures.h"
#include "random_walks.h"
#include "robust_replay_outcome.h"
#include "shared_data.h"

namespace arbor {
namespace {

using Outcome = testing::RobustOutcome;
using testing::diagonalInformation;
using testing::isotropicNoise;
using testing::replayRobust;

template <class G>
void leaveOneOutIsTheInnovationWithout() {
  constexpr int kI = 75;       // the closure kI → 79
  constexpr double kM = 40.0;  // its innovation
  std::vector<G> truth;
  const auto walk = testing::randomWalk<G>(80, 20, 11, &truth);
  IncrementalSmoother<G> without, with;
  testing::replayWalk(walk, &without, [](const auto&, const auto&) {});
  testing::replayWalk(walk, &with, [](const auto&, const auto&) {});
  without.relinearizeAll();
  // The closure kI → 79 measures the estimate's relative pose moved by `offset`, so that its
  // residual there is the offset and its innovation kM.
  typename G::Tangent offset = G::Tangent::Zero();
  offset(0) = 1.0;
  offset(1) = -0.7;
  const G between = without.estimate(kI).between(without.estimate(79));
  auto closure = [&](double alpha) {
    return RelativePoseEdge<G>::make(kI, 79, between.compose(G::Exp(alpha * offset)),
                                     diagonalInformation<G>(100.0, 400.0));
  };
  const RelativePoseEdge<G> c = closure(std::sqrt(kM / *closureInnovation(without, closure(1))));
  with.addFactor(c);
  with.update();
  without.relinearizeAll();  // each at its own optimum
  with.relinearizeAll();
  const std::optional<double> m = closureInnovation(without, c);
  const std::optional<double> m_loo = leaveOneOutInnovation(with, c);
  const std::optional<double> naive = closureInnovation(with, c);
  ASSERT_TRUE(m && m_loo && naive);
  ASSERT_GT(*m, 10.0) << "the moved closure should stand out: not this test's case";
  // Equal to first order in the step the closure causes (1.5% in 2D, 0.9% in 3D here; the
  // identity's I − AΣAᵀ has eigenvalues near 0.1 for this closure, so (L) magnifies any
  // difference between the two trees' Σ tenfold).
  EXPECT_NEAR(*m_loo, *m, 0.05 * *m);
  // (E) read on the tree that holds it sees a residual the closure has pulled in already.
  EXPECT_LT(*naive, 0.5 * *m);
  // Not in the tree at weight 1: no (L) (I − AΣAᵀ then has nothing of the closure in Σ, and
  // what it returns is not the leave-one-out innovation; the caller holds that invariant), but
  // a pose that has not been through an update has no Σ at all.
  IncrementalSmoother<G> fresh;
  fresh.addFixedPose(G());
  fresh.addPose(G());
  EXPECT_FALSE(leaveOneOutInnovation(
      fresh, RelativePoseEdge<G>::make(0, 1, G(), diagonalInformation<G>(1.0, 1.0))));
}

TEST(LeaveOneOut, IsTheInnovationWithoutTheClosure2D) { leaveOneOutIsTheInnovationWithout<SE2>(); }
TEST(LeaveOneOut, IsTheInnovationWithoutTheClosure3D) { leaveOneOutIsTheInnovationWithout<SE3>(); }

// Graduation settles a closure at weight 1 when its residual s at the estimate it has pulled
// towards is within c²; (L) asks what keeping it costs. On smallGrid3D with 90% local false
// closures (seed 1) graduation keeps the false (1, 27) at s 61.6 against c² 192.8, where (L) is
// 423.

// smallGrid3D (shared data) with false closures planted as `arbor generate outliers --seed 1`
// does, and their (from, to) pairs, low id first as Outcome::rejected has them.
using PlantedGrid = testing::PlantedGraph<SE3>;

PlantedGrid plantSmallGrid3D(double fraction, sim::OutlierPolicy policy, std::uint64_t seed = 1) {
  sim::OutlierOptions o;
  o.fraction = fraction;
  o.policy = policy;
  o.seed = seed;
  return testing::plantFalseClosures(
      std::get<PoseGraph3>(readPoseGraphFile(testing::datasetPath("smallGrid3D"))), o);
}

// The replay of `g` with `off` and with `on`, printed side by side.
std::pair<Outcome, Outcome> replayBoth(const PlantedGrid& g, const RobustOptions& off,
                                       const RobustOptions& on) {
  std::pair<Outcome, Outcome> r{replayRobust(g.clean, g.graph, off),
                                replayRobust(g.clean, g.graph, on)};
  std::cout << "rejected " << r.first.rejected.size() << " -> " << r.second.rejected.size()
            << " of " << g.is_false.size() << " false, F_clean " << r.first.F_clean << " -> "
            << r.second.F_clean << "\n";
  return r;
}

// The defaults with the final check off (margin 0).
RobustOptions withoutFinalCheck() {
  RobustOptions o;
  o.rules_off.add(RobustRule::kFinalConfirm);
  return o;
}

// Graduation keeps smallGrid3D's isolated false (58, 100) (10% random false closures, seed 1:
// pose 100 has only its odometry besides) at F_clean 1.03 F*; in finalize() its (L) is 1.41·c²,
// past the margin, and it is dropped.
TEST(LeaveOneOut, FinalizeDropsAnIsolatedFalseClosure) {
  if (!testing::datasetPresent("smallGrid3D"))
    GTEST_SKIP() << "shared dataset absent: " << testing::datasetPath("smallGrid3D");
  const PlantedGrid g = plantSmallGrid3D(0.1, sim::OutlierPolicy::kRandom);
  const auto [off, on] = replayBoth(g, withoutFinalCheck(), RobustOptions{});
  EXPECT_EQ(off.unconfirmed, 0);
  EXPECT_LT(off.rejected.size(), g.is_false.size());  // graduation keeps one
  EXPECT_GT(on.unconfirmed, 0);
  EXPECT_EQ(on.rejected, g.is_false);  // every false closure, and no true one
  EXPECT_LT(on.F_clean, off.F_clean / 1.02);
  // finalize()'s re-checks of the rejected closures: most settled by (E)'s lower bound alone.
  EXPECT_GE(on.rechecks_bounded, static_cast<int>(g.is_false.size()) / 2);
}

// Without corroboration (K = 0) nothing backs a true run, and the final check stays off: on the
// garage with 10% random false closures it would drop three more true closures there.
TEST(LeaveOneOut, FinalizeCheckNeedsCorroboration) {
  const std::string name = "robust/parking-garage_random_0.1";
  if (!testing::datasetPresent(name) || !testing::datasetPresent("parking-garage"))
    GTEST_SKIP() << "shared dataset absent: " << testing::datasetPath(name);
  const PoseGraph3 clean =
      std::get<PoseGraph3>(readPoseGraphFile(testing::datasetPath("parking-garage")));
  const PoseGraph3 graph = std::get<PoseGraph3>(readPoseGraphFile(testing::datasetPath(name)));
  RobustOptions uncorroborated;
  uncorroborated.corroboration_window = 0;
  EXPECT_EQ(replayRobust(clean, graph, uncorroborated).unconfirmed, 0);
}

// With 50% group false closures (seed 1) graduation keeps (29, 35), 6 poses long, of the group
// (24, 30)…(33, 39); the true (20, 29) "agrees" with it through an estimate the group has bent,
// so only a partner rule that asks both closures to span more than 2K poses lets the final
// check reach it.
TEST(LeaveOneOut, FinalizeDropsAShortGroupMember) {
  if (!testing::datasetPresent("smallGrid3D"))
    GTEST_SKIP() << "shared dataset absent: " << testing::datasetPath("smallGrid3D");
  const PlantedGrid g = plantSmallGrid3D(0.5, sim::OutlierPolicy::kGroup);
  const auto [off, on] = replayBoth(g, withoutFinalCheck(), RobustOptions{});
  EXPECT_LT(off.rejected.size(), g.is_false.size());
  EXPECT_EQ(on.rejected, g.is_false);
  EXPECT_LT(on.F_clean, off.F_clean / 1.02);
}

// A partner backs a closure at the end only when the two agree (P) read in both frames, within
// the closures' own c². With 50% local false closures (seed 2) the true (11, 38) read in the
// false (1, 33)'s frame agrees (62.5, under the pairs' bound of 77.9) and in its own does not
// (1005): backed so, (1, 33) escaped the final check and F_clean ended at 1.145 F*.
TEST(LeaveOneOut, FinalizeReadsAgreementInBothFrames) {
  if (!testing::datasetPresent("smallGrid3D"))
    GTEST_SKIP() << "shared dataset absent: " << testing::datasetPath("smallGrid3D");
  const PlantedGrid g = plantSmallGrid3D(0.5, sim::OutlierPolicy::kLocal, 2);
  ASSERT_TRUE(g.is_false.count({1, 33}));
  const double F_plain = testing::plainReplayF(g.clean);
  const Outcome r = replayRobust(g.clean, g.graph, RobustOptions{});
  std::cout << "rejected " << r.rejected.size() << " of " << g.is_false.size() << " false, F_clean "
            << r.F_clean << " against the clean replay's " << F_plain << "\n";
  EXPECT_TRUE(r.rejected.count({1, 33}));
  for (const auto& pair : r.rejected)
    EXPECT_TRUE(g.is_false.count(pair)) << "a true closure " << pair.first << " " << pair.second;
  EXPECT_LT(r.F_clean, 1.05 * F_plain);
}

// finalize()'s (L) drops at most one closure per pose a round, the largest m₋ first. On
// smallGrid3D with 90% local false closures (seed 1) the false (1, 27) and the true (1, 8) share
// pose 1; (1, 8) stays, every rejected closure is false, and finalize() takes few rounds. Since
// "backing left out" was deleted (issue 52: no held-out case needed it) the false (14, 53),
// which true closures read through the chains it bends back, stays in here (docs/design.md,
// "Where it fails").
TEST(LeaveOneOut, FinalizeKeepsTheTrueClosureThatSharesAPose) {
  if (!testing::datasetPresent("smallGrid3D"))
    GTEST_SKIP() << "shared dataset absent: " << testing::datasetPath("smallGrid3D");
  const PlantedGrid g = plantSmallGrid3D(0.9, sim::OutlierPolicy::kLocal, 1);
  ASSERT_TRUE(g.is_false.count({1, 27}));
  ASSERT_FALSE(g.is_false.count({1, 8}));
  const Outcome out = replayRobust(g.clean, g.graph, RobustOptions{});
  EXPECT_TRUE(out.rejected.count({1, 27}));
  EXPECT_FALSE(out.rejected.count({1, 8}));
  for (const auto& pair : out.rejected)
    EXPECT_TRUE(g.is_false.count(pair)) << "a true closure " << pair.first << " " << pair.second;
  EXPECT_GE(out.rejected.size() + 1, g.is_false.size());
  EXPECT_LT(out.finalize_iterations, 8);
}

// finalize() reaches a fixed point: a closure (E) keeps taking back at weight 0 and (L) keeps
// dropping at weight 1 stays out after its second take-back (OnlineGnc::beginFinalize), so
// allowing more rounds changes nothing.
TEST(LeaveOneOut, FinalizeReachesAFixedPoint) {
  if (!testing::datasetPresent("smallGrid3D"))
    GTEST_SKIP() << "shared dataset absent: " << testing::datasetPath("smallGrid3D");
  const PlantedGrid g = plantSmallGrid3D(0.1, sim::OutlierPolicy::kLocal, 3);
  RobustOptions longer;
  longer.finalize_rounds = 40;
  const auto [ten, forty] = replayBoth(g, RobustOptions{}, longer);
  EXPECT_EQ(ten.rejected, forty.rejected);
  EXPECT_EQ(ten.unconfirmed, forty.unconfirmed);
}

}  // namespace
}  // namespace arbor
