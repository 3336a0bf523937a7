// tools/refine/batch_refiner.h: keep-best verdicts, the one-in-flight rule, skip counting,
// synchronous and background runs on an OnlineSmoother's snapshot, reseeding from the winner;
// only the batch solvers marked for refinement are accepted.
#include <algorithm>
#include <chrono>
#include <cmath>
#include <limits>
#include <random>
#include <stdexcept>
#include <thread>
#include <utility>

#include <gtest/gtest.h>

#include "arbor_slam/tools/refine/batch_refiner.h"

namespace arbor::refine {
namespace {

const double kNaN = std::numeric_limits<double>::quiet_NaN();

// n poses going round circles of `per_circle` one metre a step, and relative measurements
// between them with N(0, σ²) noise on each tangent component.
struct NoisyCircles {
  NoisyCircles(int n, int per_circle, double sigma, unsigned seed)
      : rng(seed), noise(0, sigma), truth(static_cast<size_t>(n)) {
    for (int k = 1; k < n; ++k) truth[k] = truth[k - 1].compose(SE2(1, 0, 2 * M_PI / per_circle));
  }
  SE2 z(int a, int b) {
    return truth[a].between(truth[b]).compose(SE2(noise(rng), noise(rng), noise(rng)));
  }
  std::mt19937 rng;
  std::normal_distribution<double> noise;
  std::vector<SE2> truth;
};

TEST(PickWinner, LowestFWinsAndTheMarginIsToTheRunnerUp) {
  Verdict v = pickWinner(10.0, 9.0, 8.5);
  EXPECT_EQ(v.winner, "rtr");
  EXPECT_DOUBLE_EQ(v.margin, 0.5);
  EXPECT_DOUBLE_EQ(v.margin_relative, 0.5 / 8.5);
  // SE-Sync's relaxation is isotropic: its polished answer can lose to plain LM.
  v = pickWinner(10.0, 9.0, 42.0);
  EXPECT_EQ(v.winner, "lm");
  EXPECT_DOUBLE_EQ(v.margin, 1.0);
  v = pickWinner(10.0, 9.5, kNaN);  // lm only
  EXPECT_EQ(v.winner, "lm");
  EXPECT_DOUBLE_EQ(v.margin, 0.5);
  v = pickWinner(10.0, 10.5, 11.0);
  EXPECT_EQ(v.winner, "incremental");
  EXPECT_DOUBLE_EQ(v.margin, 0.5);
  // Not better by more than 1e-9 relative: the incremental estimate stays (no rebuild).
  v = pickWinner(10.0, 10.0 * (1 - 1e-12), kNaN);
  EXPECT_EQ(v.winner, "incremental");
  EXPECT_LT(v.margin, 1e-10);
  v = pickWinner(10.0, 9.0, 9.0);  // tie between the batch solvers: RTR
  EXPECT_EQ(v.winner, "rtr");
  EXPECT_DOUBLE_EQ(v.margin, 0.0);
}

// A noisy 2D loop with closures, fed edge by edge.
OnlineSmoother<SE2> noisySmoother(int n, unsigned seed) {
  NoisyCircles circles(n, 25, 0.1, seed);
  auto z = [&](int a, int b) { return circles.z(a, b); };
  OnlineSmoother<SE2> s;
  for (int k = 1; k < n; ++k) {
    s.addEdge(k - 1, k, z(k - 1, k), Eigen::Matrix3d::Identity());
    if (k >= 25) s.addEdge(k - 25, k, z(k - 25, k), Eigen::Matrix3d::Identity());
    s.update();
  }
  return s;
}

TEST(BatchRefiner, OneInFlightSkipsAreCountedAndTheRunIsCollected) {
  OnlineSmoother<SE2> s = noisySmoother(200, 1);
  RefinerOptions o;
  o.solver = BatchSolver::kRtr;
  o.every = 5;
  BatchRefiner<SE2> refiner(o);
  EXPECT_TRUE(refiner.due(10));
  EXPECT_FALSE(refiner.due(11));
  EXPECT_FALSE(refiner.due(0));
  ASSERT_TRUE(refiner.start(s, 10));
  EXPECT_TRUE(refiner.inFlight());
  EXPECT_FALSE(refiner.start(s, 15));  // one in flight
  EXPECT_EQ(refiner.skipped(), 1);
  const auto done = refiner.collect(true);
  ASSERT_TRUE(done.has_value());
  EXPECT_FALSE(refiner.inFlight());
  EXPECT_EQ(refiner.completed(), 1);
  const BatchRun& run = done->run;
  EXPECT_EQ(run.update, 10);
  EXPECT_EQ(run.poses, 200);
  EXPECT_GE(run.rank, 2);
  EXPECT_TRUE(std::isfinite(run.F_rtr));
  EXPECT_EQ(run.F_batch, run.F_rtr);
  EXPECT_NEAR(run.F_incremental, s.smoother().objective(), 1e-9 * run.F_incremental);
  EXPECT_EQ(pickWinner(run.F_incremental, run.F_lm, run.F_rtr).winner, run.winner);
  EXPECT_EQ(done->best.empty(), run.winner == "incremental");
  EXPECT_EQ(done->batch.size(), 200u);
  EXPECT_FALSE(refiner.collect(true).has_value());  // nothing in flight
}

TEST(BatchRefiner, SynchronousReseedLandsOnTheWinner) {
  OnlineSmoother<SE2> s = noisySmoother(150, 2);
  RefinerOptions o;
  o.solver = BatchSolver::kLevenbergMarquardt;
  o.every = 1;
  o.reseed = true;
  o.synchronous = true;
  BatchRefiner<SE2> refiner(o);
  const double before = s.smoother().objective();
  const std::vector<BatchRun> runs = refiner.afterUpdate(s, 7);
  ASSERT_EQ(runs.size(), 1u);
  const BatchRun& run = runs[0];
  EXPECT_EQ(run.update, 7);
  ASSERT_EQ(run.winner, "lm") << "LM from a mid-stream incremental estimate should improve it";
  EXPECT_TRUE(run.reseeded);
  EXPECT_EQ(refiner.reseeds(), 1);
  EXPECT_NEAR(run.F_before_reseed, before, 1e-12 * before);
  EXPECT_LE(s.smoother().objective(), run.F_lm * (1 + 1e-9));
  EXPECT_LT(s.smoother().objective(), before);
}

TEST(BatchRefiner, BackgroundRunsWhileUpdatesGoOn) {
  OnlineSmoother<SE2> s = noisySmoother(300, 3);
  RefinerOptions o;
  o.solver = BatchSolver::kRtr;
  BatchRefiner<SE2> refiner(o);
  ASSERT_TRUE(refiner.start(s, 1));
  int during = 0;
  while (refiner.running()) {  // the owner keeps updating meanwhile
    s.addEdge(1000 + during, 1001 + during, SE2(1, 0, 0), Eigen::Matrix3d::Identity());
    if (during == 0) s.addEdge(299, 1000, SE2(1, 0, 0), Eigen::Matrix3d::Identity());
    s.update();
    refiner.noteUpdate();
    ++during;
    std::this_thread::sleep_for(std::chrono::microseconds(200));
  }
  const auto done = refiner.collect(false);
  ASSERT_TRUE(done.has_value());
  EXPECT_GT(during, 0);
  // The last update may have ended after the solve did (then it is not counted).
  EXPECT_LE(done->run.updates_during, during);
  EXPECT_GE(done->run.updates_during, during - 1);
  EXPECT_EQ(done->run.poses, 300);  // the snapshot, not the poses added meanwhile
}

// Robust, with each loop closure's own kernel (edge_t's kernel, --edge-choices): the snapshot
// lists per edge the kernel the online GNC judges it by, and the batch weights every closure by
// that kernel, so its Σρ of the incremental estimate is the online GNC's own Σρ (one kernel for
// all, TLS, would count the Cauchy and Geman–McClure closures differently).
TEST(BatchRefiner, RobustBatchWeightsEachClosureByItsOwnKernel) {
  OnlineSmootherOptions<SE2> options;
  options.robust = RobustOptions{};
  OnlineSmoother<SE2> s(options);
  NoisyCircles circles(80, 20, 0.05, 5);
  auto z = [&](int a, int b) { return circles.z(a, b); };
  const KernelKind cycle[] = {KernelKind::kCauchy, KernelKind::kGemanMcClure,
                              KernelKind::kTruncatedLeastSquares};
  std::vector<KernelKind> given;  // per loop closure, in the order added
  for (int k = 1; k < 80; ++k) {
    s.addEdge(k - 1, k, z(k - 1, k), Eigen::Matrix3d::Identity() * 400);
    if (k >= 20) {
      given.push_back(cycle[k % 3]);
      s.addEdge(k - 20, k, z(k - 20, k), Eigen::Matrix3d::Identity() * 400, EdgeTrust::kByRule,
                given.back());
    }
    s.update();
  }
  SnapshotJudgement judgement;
  const PoseGraph<SE2> snapshot = s.snapshot(&judgement);
  const std::vector<char>& judged = judgement.judged;
  const std::vector<KernelKind>& kernels = judgement.kernels;
  ASSERT_EQ(kernels.size(), snapshot.edges.size());
  size_t closure = 0;
  int judged_count = 0;
  for (size_t e = 0; e < snapshot.edges.size(); ++e) {
    const bool loop = std::abs(snapshot.edges[e].i - snapshot.edges[e].j) > 1;
    if (!loop) {
      EXPECT_EQ(kernels[e], KernelKind::kNone) << "edge " << e;
      continue;
    }
    ASSERT_LT(closure, given.size());
    if (judged[e]) {
      EXPECT_EQ(kernels[e], given[closure]) << "closure " << closure;
      ++judged_count;
    }
    ++closure;
  }
  EXPECT_GT(judged_count, 40);

  RefinerOptions ro;
  ro.solver = BatchSolver::kLevenbergMarquardt;
  ro.every = 1;
  ro.synchronous = true;
  BatchRefiner<SE2> refiner(ro);
  ASSERT_TRUE(refiner.start(s, 1));
  const auto done = refiner.collect(true);
  ASSERT_TRUE(done.has_value());
  EXPECT_TRUE(done->run.robust);
  EXPECT_NEAR(done->run.F_incremental, s.robustObjective(), 1e-9 * s.robustObjective());
  // The same snapshot under one kernel for every closure counts them differently.
  GncOptions single = gncOptionsOf(*s.gnc());
  EXPECT_GT(std::abs(robustCost(snapshot, snapshot.poses, judged, single) - s.robustObjective()),
            1e-6 * s.robustObjective());
}

// OnlineSmoother::snapshot's judgement names the closures the online GNC does not hold as
// settled inliers (what a robust batch from a finalized smoother holds out,
// tools/refine/gnc_from_online.h): after finalize(), the rejected ones, here the three planted.
TEST(BatchRefiner, TheSnapshotNamesTheClosuresTheSmootherRejects) {
  OnlineSmootherOptions<SE2> options;
  options.robust = RobustOptions{};
  OnlineSmoother<SE2> s(options);
  NoisyCircles circles(80, 20, 0.05, 7);
  auto z = [&](int a, int b) { return circles.z(a, b); };
  const Eigen::Matrix3d omega = Eigen::Matrix3d::Identity() * 400;
  const std::vector<std::pair<Key, Key>> planted = {{30, 55}, {41, 66}, {52, 77}};
  for (int k = 1; k < 80; ++k) {
    s.addEdge(k - 1, k, z(k - 1, k), omega);
    if (k >= 20) s.addEdge(k - 20, k, z(k - 20, k), omega);
    for (const auto& [a, b] : planted)
      if (k == b) s.addEdge(a, b, SE2(4, -3, 1.2), omega);
    s.update();
  }
  EXPECT_FALSE(s.finalized());
  s.finalize();
  EXPECT_TRUE(s.finalized());  // a robust batch now starts from this classification
  SnapshotJudgement judgement;
  const PoseGraph<SE2> snapshot = s.snapshot(&judgement);
  ASSERT_EQ(judgement.held_out.size(), snapshot.edges.size());
  ASSERT_EQ(judgement.judged.size(), snapshot.edges.size());
  std::vector<std::pair<Key, Key>> rejected;
  for (size_t e = 0; e < snapshot.edges.size(); ++e) {
    if (!judgement.held_out[e]) continue;
    EXPECT_TRUE(judgement.judged[e]) << "edge " << e;
    const auto& edge = snapshot.edges[e];
    rejected.emplace_back(snapshot.ids[static_cast<size_t>(edge.i)],
                          snapshot.ids[static_cast<size_t>(edge.j)]);
  }
  std::sort(rejected.begin(), rejected.end());
  EXPECT_EQ(rejected, planted);
  EXPECT_EQ(static_cast<int>(rejected.size()), s.stats().closures_outlier);
  s.addEdge(79, 80, z(79, 0), omega);  // anything added: the classification is provisional
  EXPECT_FALSE(s.finalized());
  s.update();
  EXPECT_FALSE(s.finalized());
}

TEST(BatchRefiner, RefusesBadOptionsAndTinySnapshots) {
  RefinerOptions o;
  o.every = -1;
  EXPECT_THROW(BatchRefiner<SE2>{o}, std::invalid_argument);
  // Only the table's rows marked `refines` run as the refinement.
  for (const BatchSolverInfo& row : batchSolvers()) {
    RefinerOptions r;
    r.solver = row.solver;
    if (row.refines) {
      EXPECT_NO_THROW(BatchRefiner<SE2>{r}) << row.name;
    } else {
      EXPECT_THROW(BatchRefiner<SE2>{r}, std::invalid_argument) << row.name;
      EXPECT_THROW(solveSnapshot(row.solver, PoseGraph<SE2>{}), std::invalid_argument) << row.name;
    }
  }
  BatchRefiner<SE2> refiner;
  OnlineSmoother<SE2> empty;
  EXPECT_FALSE(refiner.start(empty, 0));
  EXPECT_EQ(refiner.skipped(), 0);
  EXPECT_FALSE(refiner.inFlight());
}

}  // namespace
}  // namespace arbor::refine
