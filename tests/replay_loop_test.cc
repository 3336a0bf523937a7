// Batch refinement in the replay loop (issue 5, "The loop"): background LM / RTR runs on
// snapshots, skip accounting, reseeding the smoother from a better batch estimate.
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <limits>
#include <utility>

#include <nlohmann/json.hpp>

#include "arbor_slam/io/pose_graph_file.h"
#include "arbor_slam/tests/shared_data.h"
#include "arbor_slam/tools/cli/batch_refinement.h"
#include "arbor_slam/tools/cli/cli_common.h"
#include "arbor_slam/tools/cli/commands.h"
#include "arbor_slam/tools/generator/graph_generator.h"

namespace arbor::cli {
namespace {

PoseGraph<SE2> manhattan(int poses, double sigma_rotation, std::uint64_t seed) {
  sim::ManhattanOptions o;
  o.poses = poses;
  o.grid = 6;
  o.noise = {0.05, sigma_rotation};
  o.seed = seed;
  return sim::manhattanWorld(o).graph;
}

void expectConsistent(const BatchRun& b) {
  EXPECT_GT(b.poses, 1);
  EXPECT_GT(b.edges, 0);
  EXPECT_TRUE(std::isfinite(b.F_batch));
  EXPECT_NEAR(b.relative_gap, (b.F_incremental - b.F_batch) / b.F_batch, 1e-9);
  const bool rtr = b.rank > 0;
  EXPECT_EQ(std::isfinite(b.F_rtr), rtr);
  if (!rtr) {
    EXPECT_EQ(b.F_lm, b.F_batch);
  } else {
    EXPECT_EQ(b.F_rtr, b.F_batch);
  }
  // Keep-best: the winner has the lowest F of the candidates, and the margin is to the next.
  std::vector<std::pair<std::string, double>> candidates{{"incremental", b.F_incremental},
                                                         {"lm", b.F_lm}};
  if (rtr) candidates.push_back({"rtr", b.F_rtr});
  double winner_F = -1, runner_up = std::numeric_limits<double>::infinity();
  for (const auto& [name, F] : candidates) {
    if (name == b.winner) winner_F = F;
  }
  ASSERT_GE(winner_F, 0) << "winner " << b.winner;
  for (const auto& [name, F] : candidates) {
    EXPECT_GE(F, winner_F * (1 - 1e-9)) << name << " beats the winner " << b.winner;
    if (name != b.winner) runner_up = std::min(runner_up, F);
  }
  EXPECT_NEAR(b.margin, std::abs(runner_up - winner_F), 1e-9 * winner_F + 1e-12);
  EXPECT_NEAR(b.margin_relative, b.margin / winner_F, 1e-12);
  if (b.winner != "incremental") {
    EXPECT_LT(winner_F, b.F_incremental);
  }
  EXPECT_GE(b.max_translation_diff, 0.0);
  EXPECT_GE(b.max_rotation_diff, 0.0);
  EXPECT_LE(b.max_rotation_diff, M_PI + 1e-9);
  EXPECT_GT(b.time_s, 0.0);
  EXPECT_NEAR(b.time_s, b.lm_time_s + b.rtr_time_s, 1e-12);
}

TEST(ReplayLoop, LmEveryNUpdatesCountsRunsAndNeverLosesToIncremental) {
  const PoseGraph<SE2> graph = manhattan(300, 0.01, 3);
  ReplaySettings settings;
  BatchLoopSettings loop;
  loop.solver = BatchSolver::kLevenbergMarquardt;
  loop.every = 40;
  const LoopResult<SE2> r = runReplayWithBatches(graph, settings, loop);
  const int updates = static_cast<int>(r.replay.rows.size());
  ASSERT_EQ(updates, graph.numEdges());
  ASSERT_FALSE(r.batches.empty());
  ASSERT_TRUE(r.batches.back().final_run);
  const int background = static_cast<int>(r.batches.size()) - 1;
  EXPECT_EQ(background + r.skipped, updates / loop.every);
  EXPECT_GT(background, 0);
  int previous = 0, during = 0;
  for (const BatchRun& b : r.batches) {
    expectConsistent(b);
    // LM starts from the incremental estimate and accepts only decreasing steps.
    EXPECT_LE(b.F_batch, b.F_incremental * (1 + 1e-9));
    EXPECT_FALSE(b.reseeded);
    EXPECT_EQ(b.rank, 0);
    if (!b.final_run) {
      EXPECT_EQ(b.update % loop.every, 0);
      EXPECT_GT(b.update, previous);
      previous = b.update;
      during += b.updates_during;
    }
  }
  EXPECT_EQ(r.batches.back().poses, graph.numPoses());
  EXPECT_EQ(r.batches.back().edges, graph.numEdges());
  EXPECT_NEAR(r.replay.batch.F_final, r.batches.back().F_batch, 1e-9 * r.replay.F_final);
  EXPECT_GT(during, 0) << "no update ran while a batch was in the background";
  EXPECT_EQ(r.reseeds, 0);
}

TEST(ReplayLoop, IncrementalMatchesPlainReplayWithoutReseeding) {
  const PoseGraph<SE2> graph = manhattan(200, 0.01, 5);
  ReplaySettings settings;
  settings.batch = false;
  const ReplayResult<SE2> plain = runReplay(graph, settings);
  BatchLoopSettings loop;
  loop.every = 25;
  const LoopResult<SE2> r = runReplayWithBatches(graph, settings, loop);
  EXPECT_NEAR(r.replay.F_incremental, plain.F_incremental, 1e-9 * plain.F_incremental);
  EXPECT_NEAR(r.replay.F_final, plain.F_final, 1e-9 * plain.F_final);
  EXPECT_EQ(r.replay.duplicates, plain.duplicates);
  EXPECT_EQ(r.replay.pending, plain.pending);
}

TEST(ReplayLoop, RtrReportsCertificateAndUpdatesContinueMeanwhile) {
  const PoseGraph<SE2> graph = manhattan(300, 0.05, 7);
  ReplaySettings settings;
  BatchLoopSettings loop;
  loop.solver = BatchSolver::kRtr;
  loop.every = 60;
  const LoopResult<SE2> r = runReplayWithBatches(graph, settings, loop);
  ASSERT_GE(r.batches.size(), 2u);
  double longest = 0;
  int during = 0;
  for (const BatchRun& b : r.batches) {
    expectConsistent(b);
    EXPECT_GE(b.rank, 2);
    if (!b.final_run) during += b.updates_during;
    if (!b.final_run) longest = std::max(longest, b.time_s);
  }
  EXPECT_GT(during, 0);
  // No update waited for a whole background solve (when a solve is long enough to tell).
  if (longest > 0.05) {
    EXPECT_LT(r.replay.latency.max, 1e3 * longest);
  }
}

TEST(ReplayLoop, ReseedingFromBetterBatchEstimates) {
  // Large rotation noise: the incremental estimate settles in a worse optimum than RTR's.
  // Synchronous runs make the reseed points deterministic.
  const PoseGraph<SE2> graph = manhattan(300, 0.2, 11);
  ReplaySettings settings;
  BatchLoopSettings loop;
  loop.solver = BatchSolver::kRtr;
  loop.every = 50;
  loop.synchronous = true;
  const LoopResult<SE2> without = runReplayWithBatches(graph, settings, loop);
  loop.reseed = true;
  const LoopResult<SE2> with = runReplayWithBatches(graph, settings, loop);
  ASSERT_EQ(with.batches.size(), without.batches.size());
  EXPECT_EQ(with.skipped, 0);
  bool batch_won = false;
  for (const BatchRun& b : without.batches) {
    batch_won |= b.winner != "incremental" && !b.final_run;
  }
  ASSERT_TRUE(batch_won) << "pick a graph where a batch run beats the incremental estimate";
  EXPECT_GT(with.reseeds, 0);
  double final_batch = 0;
  for (size_t k = 0; k < with.batches.size(); ++k) {
    const BatchRun& b = with.batches[k];
    expectConsistent(b);
    // Synchronous: the smoother holds exactly the snapshot, so a winning batch is always kept.
    EXPECT_EQ(b.reseeded, b.winner != "incremental");
    EXPECT_FALSE(b.reseed_rejected);
    EXPECT_EQ(b.update, without.batches[k].update);
    if (b.reseeded && !b.final_run) {
      EXPECT_GT(b.reseed_s, 0.0);
      EXPECT_GE(b.reseed_update, b.update);
      // Synchronous: the smoother holds exactly the snapshot, so the rebuild lands on the batch
      // optimum (one Gauss–Newton step from it) and below the incremental F it replaced.
      EXPECT_LE(b.F_after_reseed, std::min(b.F_lm, b.F_rtr) * (1 + 1e-6));
      EXPECT_LT(b.F_after_reseed, b.F_before_reseed);
    }
    // Up to the first reseed both replays are identical.
    if (k == 0) {
      EXPECT_NEAR(b.F_incremental, without.batches[k].F_incremental, 1e-9 * b.F_incremental);
    }
    if (b.final_run) final_batch = b.F_batch;
  }
  EXPECT_LE(with.replay.F_final, final_batch * (1 + 1e-9));
  EXPECT_LE(with.replay.F_final, without.replay.F_final * (1 + 1e-6));
  EXPECT_EQ(with.replay.rows.size(), without.replay.rows.size());
}

TEST(ReplayLoop, BackgroundReseedKeepsUpdating) {
  const PoseGraph<SE2> graph = manhattan(300, 0.2, 11);
  ReplaySettings settings;
  BatchLoopSettings loop;
  loop.solver = BatchSolver::kRtr;
  loop.every = 50;
  loop.reseed = true;
  const LoopResult<SE2> r = runReplayWithBatches(graph, settings, loop);
  ASSERT_EQ(static_cast<int>(r.replay.rows.size()), graph.numEdges());
  double summed = 0;
  for (const BatchRun& b : r.batches) {
    expectConsistent(b);
    EXPECT_FALSE(b.reseeded && b.reseed_rejected);
    if ((b.reseeded || b.reseed_rejected) && !b.final_run) {
      summed += b.reseed_s;
      EXPECT_GE(b.reseed_update, b.update);
      EXPECT_TRUE(std::isfinite(b.F_after_reseed));
      // Kept exactly when the rebuild lowered F over everything the smoother held.
      EXPECT_EQ(b.reseeded, b.F_after_reseed < b.F_before_reseed);
    }
  }
  EXPECT_NEAR(summed, r.reseed_s, 1e-12);
  EXPECT_LE(r.replay.F_final, r.batches.back().F_batch * (1 + 1e-9));
}

TEST(ReplayLoop, RejectsNegativePeriodAndASolverThatDoesNotRefine) {
  const PoseGraph<SE2> graph = manhattan(20, 0.01, 1);
  BatchLoopSettings loop;
  loop.every = -1;
  EXPECT_THROW(runReplayWithBatches(graph, ReplaySettings{}, loop), std::invalid_argument);
  loop.every = 0;
  loop.solver = BatchSolver::kGaussNewton;
  EXPECT_THROW(runReplayWithBatches(graph, ReplaySettings{}, loop), std::invalid_argument);
}

TEST(ReplayLoop, CommandLineReportsBatchesInJson) {
  const PoseGraph<SE2> graph = manhattan(120, 0.05, 2);
  const std::string path = ::testing::TempDir() + "replay_loop_cli.g2o";
  writeG2oFile(path, graph, graph.poses);
  ::testing::internal::CaptureStdout();
  const int status =
      replayCommand({path, "--batch", "rtr", "--batch-every", "30", "--reseed", "--json"});
  const std::string out = ::testing::internal::GetCapturedStdout();
  ASSERT_EQ(status, 0);
  const nlohmann::json j = nlohmann::json::parse(out);
  ASSERT_TRUE(j.contains("batches"));
  const auto& runs = j["batches"];
  const int updates = j["updates"];
  EXPECT_EQ(static_cast<int>(runs.size()) - 1 + j["batches_skipped"].get<int>(), updates / 30);
  EXPECT_TRUE(runs.back()["final"].get<bool>());
  for (const auto& b : runs) {
    EXPECT_TRUE(b.contains("rank"));
    EXPECT_TRUE(b.contains("lambda_min"));
    EXPECT_TRUE(b.contains("certified"));
    // Keep-best figures: F of each candidate, the winner and its margin.
    EXPECT_TRUE(b.contains("F_lm"));
    EXPECT_TRUE(b.contains("F_rtr"));
    EXPECT_TRUE(b.contains("margin_relative"));
    const std::string winner = b["winner"];
    EXPECT_TRUE(winner == "incremental" || winner == "lm" || winner == "rtr") << winner;
    const double winner_F = winner == "incremental" ? b["F_incremental"].get<double>()
                            : winner == "lm"        ? b["F_lm"].get<double>()
                                                    : b["F_rtr"].get<double>();
    EXPECT_LE(winner_F, b["F_lm"].get<double>() * (1 + 1e-9));
    EXPECT_LE(winner_F, b["F_rtr"].get<double>() * (1 + 1e-9));
    EXPECT_GT(b["poses"].get<int>(), 1);
  }
  EXPECT_THROW(replayCommand({path, "--batch", "gn"}), UsageError);
  EXPECT_THROW(replayCommand({path, "--batch-every", "5"}), UsageError);
  std::remove(path.c_str());
}

// --batch-sync: every due batch runs at its snapshot on the replay thread, none is skipped,
// and two runs report the same batches and reseeds.
TEST(ReplayLoop, SynchronousBatchesAreTheSameOnEveryRun) {
  const PoseGraph<SE2> graph = manhattan(120, 0.05, 3);
  const std::string path = ::testing::TempDir() + "replay_loop_sync.g2o";
  writeG2oFile(path, graph, graph.poses);
  auto run = [&] {
    ::testing::internal::CaptureStdout();
    const int status = replayCommand({path, "--robust", "--batch", "lm", "--batch-every", "20",
                                      "--reseed", "--batch-sync", "--json"});
    const std::string out = ::testing::internal::GetCapturedStdout();
    EXPECT_EQ(status, 0);
    return nlohmann::json::parse(out);
  };
  const nlohmann::json a = run(), b = run();
  EXPECT_TRUE(a["batch_sync"].get<bool>());
  EXPECT_EQ(a["batches_skipped"].get<int>(), 0);
  const int updates = a["updates"];
  ASSERT_EQ(static_cast<int>(a["batches"].size()), updates / 20 + 1);  // and the final one
  ASSERT_EQ(a["batches"].size(), b["batches"].size());
  for (size_t k = 0; k < a["batches"].size(); ++k) {
    SCOPED_TRACE("batch " + std::to_string(k));
    EXPECT_EQ(a["batches"][k]["update"], b["batches"][k]["update"]);
    EXPECT_EQ(a["batches"][k]["updates_during"].get<int>(), 0);
    EXPECT_EQ(a["batches"][k]["F_batch"], b["batches"][k]["F_batch"]);
    EXPECT_EQ(a["batches"][k]["winner"], b["batches"][k]["winner"]);
    EXPECT_EQ(a["batches"][k]["reseeded"], b["batches"][k]["reseeded"]);
  }
  EXPECT_EQ(a["F_final"], b["F_final"]);
  EXPECT_EQ(a["reseeds"], b["reseeds"]);
  EXPECT_THROW(replayCommand({path, "--batch-sync"}), UsageError);
  std::remove(path.c_str());
}

// M3500b (M3500 with large rotation noise): the incremental estimate alone settles in a poor
// optimum (GTSAM's iSAM2 aborts); with RTR batches every 1000 updates and reseeding it ends at
// least as low as the batch estimate of the complete graph.
TEST(ReplayLoop, ReseedOnM3500bEndsNoWorseThanTheBatch) {
  if (!arbor::testing::datasetPresent("M3500b")) {
    GTEST_SKIP() << arbor::testing::datasetPath("M3500b") << " is missing";
  }
  AnyPoseGraph any = readPoseGraphFile(arbor::testing::datasetPath("M3500b"));
  const auto& graph = std::get<PoseGraph<SE2>>(any);
  ReplaySettings settings;
  BatchLoopSettings loop;
  loop.solver = BatchSolver::kRtr;
  loop.every = 1000;
  loop.reseed = true;
  loop.synchronous = true;  // deterministic: the reseeds happen at the snapshots
  const LoopResult<SE2> r = runReplayWithBatches(graph, settings, loop);
  ASSERT_GE(r.batches.size(), 2u);
  const BatchRun& last = r.batches.back();
  ASSERT_TRUE(last.final_run);
  EXPECT_GT(r.reseeds, 0);
  for (const BatchRun& b : r.batches) expectConsistent(b);
  // The smoother's own final estimate (before the final keep-best) and the reported one.
  EXPECT_LE(last.F_incremental, last.F_batch * (1 + 1e-6))
      << "reseeded smoother " << last.F_incremental << " vs batch " << last.F_batch;
  EXPECT_LE(r.replay.F_final, last.F_batch * (1 + 1e-9));
  const auto table = arbor::testing::optimumTable();
  if (table.count("M3500b")) {
    EXPECT_LE(r.replay.F_final, table.at("M3500b").F_star * (1 + 1e-4));
  }
}

}  // namespace
}  // namespace arbor::cli
