// core/cancellation.h and the solvers that check it: LM, GN and dogleg (core/batch_solver.h),
// the Riemannian staircase (core/riemannian_staircase.h, inside tCG too), GNC
// (core/gnc_solver.h) and the background refiner (tools/refine/batch_refiner.h). Every
// cancellation here is deterministic: the token is cancelled before the solve starts, or counts
// down its checks (cancelAfterChecks) so that it trips after a known iteration. No thread races
// a solve.
#include <cmath>
#include <random>
#include <vector>

#include <gtest/gtest.h>

#include "arbor_slam/bayestree/online_smoother.h"
#include "arbor_slam/core/batch_solver.h"
#include "arbor_slam/core/cancellation.h"
#include "arbor_slam/core/gnc_solver.h"
#include "arbor_slam/core/initialization.h"
#include "arbor_slam/core/riemannian_staircase.h"
#include "arbor_slam/tools/generator/graph_generator.h"
#include "arbor_slam/tools/refine/batch_refiner.h"

namespace arbor {
namespace {

PoseGraph2 noisyManhattan(int poses, std::uint64_t seed) {
  sim::ManhattanOptions o;
  o.poses = poses;
  o.grid = 6;
  o.noise = {0.05, 0.1};
  o.seed = seed;
  return sim::manhattanWorld(o).graph;
}

bool finite(const std::vector<SE2>& poses) {
  for (const SE2& x : poses)
    if (!std::isfinite(x.translation().squaredNorm()) || !std::isfinite(x.angle())) return false;
  return true;
}

TEST(CancellationToken, CopiesShareOneFlag) {
  const CancellationToken a;
  const CancellationToken b = a;
  const CancellationToken other;
  EXPECT_TRUE(a.sharesFlagWith(b));
  EXPECT_FALSE(a.sharesFlagWith(other));
  EXPECT_FALSE(b.cancelled());
  a.cancel();
  EXPECT_TRUE(b.cancelled());
  EXPECT_FALSE(other.cancelled());
  b.reset();
  EXPECT_FALSE(a.cancelled());
}

TEST(CancellationToken, CountdownTripsAtTheGivenCheck) {
  const CancellationToken t;
  t.cancelAfterChecks(2);
  EXPECT_FALSE(t.cancelled());
  EXPECT_FALSE(t.cancelled());
  EXPECT_TRUE(t.cancelled());
  EXPECT_TRUE(t.cancelled());  // stays cancelled
  t.reset();
  EXPECT_FALSE(t.cancelled());
  t.cancelAfterChecks(0);
  EXPECT_TRUE(t.cancelled());
}

TEST(CancellationToken, TerminationName) {
  EXPECT_EQ(toString(Termination::kCancelled), "cancelled");
}

class BatchCancel : public ::testing::TestWithParam<BatchMethod> {};

// Cancelled after the first iteration: one iteration, marked cancelled, F no higher than at the
// start and equal to F at the poses returned (the best iterate so far).
TEST_P(BatchCancel, AfterOneIterationReturnsTheBestIterate) {
  const PoseGraph2 graph = noisyManhattan(300, 5);
  const std::vector<SE2> start = odometryInitialization(graph);
  BatchOptions options;
  options.method = GetParam();
  std::vector<SE2> full_poses = start;
  const BatchSummary full = solveBatch(graph, &full_poses, options);
  ASSERT_GE(full.iterations, 3) << full.message;
  ASSERT_NE(full.termination, Termination::kCancelled);

  options.cancel.cancelAfterChecks(1);  // the check before iteration 2 trips
  std::vector<SE2> poses = start;
  const BatchSummary cut = solveBatch(graph, &poses, options);
  EXPECT_EQ(cut.termination, Termination::kCancelled) << cut.message;
  EXPECT_EQ(cut.iterations, 1);
  EXPECT_LT(cut.iterations, full.iterations);
  EXPECT_TRUE(finite(poses));
  EXPECT_TRUE(std::isfinite(cut.F_final));
  EXPECT_LE(cut.F_final, cut.F_initial);
  EXPECT_NEAR(cut.F_final, objective(graph, poses), 1e-9 * cut.F_initial);
}

TEST_P(BatchCancel, BeforeTheStartLeavesThePosesAsGiven) {
  const PoseGraph2 graph = noisyManhattan(100, 6);
  const std::vector<SE2> start = odometryInitialization(graph);
  BatchOptions options;
  options.method = GetParam();
  options.cancel.cancel();
  std::vector<SE2> poses = start;
  const BatchSummary s = solveBatch(graph, &poses, options);
  EXPECT_EQ(s.termination, Termination::kCancelled);
  EXPECT_EQ(s.iterations, 0);
  EXPECT_EQ(s.F_final, s.F_initial);
  for (size_t k = 0; k < poses.size(); ++k)
    EXPECT_EQ((poses[k].translation() - start[k].translation()).norm(), 0.0);
}

INSTANTIATE_TEST_SUITE_P(Methods, BatchCancel,
                         ::testing::Values(BatchMethod::kGaussNewton,
                                           BatchMethod::kLevenbergMarquardt, BatchMethod::kDogleg),
                         [](const auto& info) { return toString(info.param); });

// The staircase's checks: before each trust-region iteration and inside tCG. With the second
// check tripping (the first tCG iteration passed, the second cancelled) the level ends after one
// trust-region iteration; the estimate is the rounded staircase point, uncertified, polished by
// nothing (the polish sees the same token).
TEST(RtrCancel, InsideTheFirstTcgStopsAfterOneIteration) {
  const PoseGraph2 graph = noisyManhattan(300, 7);
  std::vector<SE2> full_poses;
  const RtrSummary full = solveRtr(graph, &full_poses);
  ASSERT_GT(full.rtr_iterations, 2) << full.message;
  ASSERT_GT(full.tcg_iterations, full.rtr_iterations) << "tCG must run more than once";
  ASSERT_FALSE(full.cancelled);

  RtrOptions options;
  options.cancel.cancelAfterChecks(1);
  std::vector<SE2> poses;
  const RtrSummary cut = solveRtr(graph, &poses, options);
  EXPECT_TRUE(cut.cancelled) << cut.message;
  EXPECT_FALSE(cut.certified);
  EXPECT_EQ(cut.rtr_iterations, 1);
  EXPECT_LT(cut.rtr_iterations, full.rtr_iterations);
  EXPECT_LE(cut.sesync_objective, cut.sesync_objective_initial);
  ASSERT_EQ(poses.size(), static_cast<size_t>(graph.numPoses()));
  EXPECT_TRUE(finite(poses));
  EXPECT_TRUE(std::isfinite(cut.F_final));
}

TEST(RtrCancel, BeforeTheStartRoundsTheChordalStart) {
  const PoseGraph2 graph = noisyManhattan(100, 8);
  RtrOptions options;
  options.cancel.cancel();
  std::vector<SE2> poses;
  const RtrSummary s = solveRtr(graph, &poses, options);
  EXPECT_TRUE(s.cancelled);
  EXPECT_EQ(s.rtr_iterations, 0);
  EXPECT_EQ(s.sesync_objective, s.sesync_objective_initial);
  EXPECT_TRUE(finite(poses));
  EXPECT_EQ(s.F_final, s.F_rounded);  // the polish took no step
}

// The Manhattan graph with `count` false loop closures (identity measurements between random
// poses far apart): GNC has steps to take.
PoseGraph2 withFalseClosures(PoseGraph2 graph, int count, std::uint64_t seed) {
  std::mt19937_64 rng(seed);
  std::uniform_int_distribution<int> pose(0, graph.numPoses() - 1);
  const auto information = graph.edges.front().information;
  for (int added = 0; added < count;) {
    const int i = pose(rng), j = pose(rng);
    if (std::abs(i - j) < 20) continue;
    graph.edges.push_back(RelativePoseEdge<SE2>::make(i, j, SE2(0.5, 0.0, 1.0), information));
    ++added;
  }
  return graph;
}

TEST(GncCancel, DuringTheLeastSquaresStartKeepsItsBestIterate) {
  const PoseGraph2 graph = withFalseClosures(noisyManhattan(200, 9), 5, 1);
  const std::vector<SE2> start = odometryInitialization(graph);
  std::vector<SE2> full_poses = start;
  const GncResult full = solveGnc(graph, &full_poses);
  ASSERT_GT(full.iterations, 1) << full.message;
  ASSERT_FALSE(full.cancelled);

  GncOptions options;
  options.cancel.cancelAfterChecks(1);  // LM of x⁰: one iteration
  std::vector<SE2> poses = start;
  const GncResult cut = solveGnc(graph, &poses, options);
  EXPECT_TRUE(cut.cancelled) << cut.message;
  EXPECT_FALSE(cut.converged);
  EXPECT_EQ(cut.iterations, 0);
  EXPECT_EQ(cut.lm_iterations, 1);
  EXPECT_TRUE(finite(poses));
  EXPECT_LE(cut.F_all, objective(graph, start));
}

TEST(GncCancel, BetweenStepsStopsBeforeTheFullRun) {
  const PoseGraph2 graph = withFalseClosures(noisyManhattan(200, 9), 5, 1);
  const std::vector<SE2> start = odometryInitialization(graph);
  std::vector<SE2> full_poses = start;
  const GncResult full = solveGnc(graph, &full_poses);
  ASSERT_GT(full.iterations, 1) << full.message;
  // Wherever the count lands (x⁰'s solve, a GNC step or its inner solve), the run is cut short.
  for (int checks : {full.lm_iterations / 4, full.lm_iterations / 2}) {
    GncOptions options;
    options.cancel.cancelAfterChecks(checks);
    std::vector<SE2> poses = start;
    const GncResult cut = solveGnc(graph, &poses, options);
    EXPECT_TRUE(cut.cancelled) << checks << ": " << cut.message;
    EXPECT_LT(cut.lm_iterations, full.lm_iterations) << checks;
    EXPECT_LE(cut.iterations, full.iterations) << checks;
    EXPECT_TRUE(finite(poses)) << checks;
    EXPECT_TRUE(std::isfinite(cut.F_all)) << checks;
  }
}

// The refiner hands its token to every solve; a cancelled run is marked and has no winner
// estimate, so it never reseeds.
TEST(RefinerCancel, ACancelledBatchIsMarkedAndDoesNotReseed) {
  const PoseGraph2 graph = noisyManhattan(200, 10);
  for (refine::BatchSolver solver :
       {refine::BatchSolver::kLevenbergMarquardt, refine::BatchSolver::kRtr}) {
    OnlineSmoother2 smoother;
    for (const auto& e : graph.edges) {
      smoother.addEdge(graph.ids[e.i], graph.ids[e.j], e.measurement, e.information);
      smoother.update();
    }
    refine::RefinerOptions options;
    options.solver = solver;
    options.reseed = true;
    options.synchronous = true;
    refine::BatchRefiner<SE2> refiner(options);
    options.cancel.cancel();  // a copy: the refiner's token is the same flag
    ASSERT_TRUE(refiner.start(smoother, 1));
    auto done = refiner.collect(true);
    ASSERT_TRUE(done.has_value());
    EXPECT_TRUE(done->run.cancelled) << refine::toString(solver);
    EXPECT_TRUE(done->best.empty());
    EXPECT_TRUE(std::isfinite(done->run.F_lm));
    EXPECT_LE(done->run.F_lm, done->run.F_incremental * (1 + 1e-12));
    EXPECT_FALSE(refiner.reseed(smoother, &*done, 1));
  }
}

}  // namespace
}  // namespace arbor
