// Batch refinement in `arbor serve` (issue 5, "The loop"), in process over memq://: command
// BATCH gives a status with the run's figures; --batch-every with --reseed in lockstep ends no
// worse than without; a restart from the journal after reseeds reproduces the estimate exactly.
#include <algorithm>
#include <chrono>
#include <condition_variable>
#include <cstdio>
#include <filesystem>
#include <functional>
#include <iostream>
#include <mutex>
#include <string>
#include <thread>

#include <gtest/gtest.h>
#include <unistd.h>

#include "arbor_slam/io/lcm_messages.h"
#include "arbor_slam/tests/lcm_test_support.h"
#include "arbor_slam/tools/cli/cli_common.h"
#include "arbor_slam/tools/cli/commands.h"
#include "arbor_slam/tools/cli/replay_order.h"
#include "arbor_slam/tools/generator/graph_generator.h"
#include "arbor_slam/tools/serve/serve_service.h"

namespace arbor::serve {
namespace {

using testing::Collector;
using testing::edgeBytes;
using testing::replayOrder;

PoseGraph2 noisyGraph(int poses, double sigma_rotation, std::uint64_t seed) {
  return testing::manhattanGraph(poses, 6, sigma_rotation, seed);
}

void sendCommand(lcm::LCM& lcm, const Service& service, std::int8_t kind) {
  command_t c;
  c.utime = 0;
  c.command = kind;
  c.path = "";
  const auto b = encodeMessage(c);
  lcm.publish(service.channels().command, b.data(), static_cast<unsigned>(b.size()));
}

// Streams order[from, to) one edge at a time, each waited for (one update per edge).
void lockstep(lcm::LCM& lcm, const Service& service, Collector& collector, const PoseGraph2& graph,
              const std::vector<int>& order, size_t from, size_t to) {
  for (size_t k = from; k < to; ++k) {
    const auto b = edgeBytes(graph, order[k], static_cast<std::int64_t>(k) + 1);
    lcm.publish(service.channels().edges, b.data(), static_cast<unsigned>(b.size()));
    ASSERT_TRUE(collector.waitCovered(static_cast<std::int64_t>(k) + 1)) << "edge " << k;
  }
}

std::string tempPath(const std::string& name) {
  return testing::tempPath("arbor_serve_batch", name);
}

TEST(LcmServeBatch, CommandBatchPublishesTheRunInStatus) {
  const PoseGraph2 graph = noisyGraph(150, 0.05, 3);
  const std::vector<int> order = replayOrder(graph);
  lcm::LCM lcm("memq://");
  ServeOptions options;
  options.refine_on_exit = false;
  options.batch.solver = refine::BatchSolver::kRtr;  // no --batch-every: only on command
  Service service(lcm, options);
  Collector collector(lcm, service.channels());
  service.start();
  for (size_t k = 0; k < order.size(); ++k) {
    const auto b = edgeBytes(graph, order[k], static_cast<std::int64_t>(k) + 1);
    lcm.publish(service.channels().edges, b.data(), static_cast<unsigned>(b.size()));
  }
  ASSERT_TRUE(collector.waitCovered(static_cast<std::int64_t>(order.size())));
  EXPECT_EQ(service.status().batches, 0);
  EXPECT_EQ(service.status().batch_winner, "");
  sendCommand(lcm, service, command_t::BATCH);
  ASSERT_TRUE(collector.waitStatus([](const status_t& s) { return s.batches == 1; }));
  service.stop();
  const status_t s = collector.status();
  EXPECT_EQ(s.batch_poses, graph.numPoses());
  EXPECT_EQ(s.batch_update, service.summary().updates);
  EXPECT_GT(s.batch_F_incremental, 0);
  EXPECT_LE(s.batch_F_lm, s.batch_F_incremental * (1 + 1e-9));
  EXPECT_NEAR(s.batch_relative_gap, (s.batch_F_incremental - s.batch_F) / s.batch_F, 1e-9);
  EXPECT_TRUE(s.batch_winner == "incremental" || s.batch_winner == "lm" || s.batch_winner == "rtr")
      << s.batch_winner;
  EXPECT_GE(s.batch_rank, 2);  // RTR ran
  EXPECT_GT(s.batch_time_s, 0);
  EXPECT_GE(s.batch_max_translation_diff, 0);
  EXPECT_GE(s.batch_margin, 0);
  EXPECT_FALSE(s.batch_reseeded);  // no --reseed
  EXPECT_EQ(s.reseeds, 0);
  ASSERT_EQ(service.summary().batches.size(), 1u);
  EXPECT_EQ(service.summary().batches[0].winner, s.batch_winner);
}

TEST(LcmServeBatch, ReseedingInLockstepEndsNoWorse) {
  // Large rotation noise: batch estimates beat the incremental one (as in replay_loop_test).
  const PoseGraph2 graph = noisyGraph(300, 0.2, 11);
  const std::vector<int> order = replayOrder(graph);
  auto run = [&](bool reseed) {
    lcm::LCM lcm("memq://");
    ServeOptions options;
    options.batch.solver = refine::BatchSolver::kRtr;
    options.batch.every = 50;
    options.batch.reseed = reseed;
    options.batch.synchronous = true;  // deterministic reseed points
    Service service(lcm, options);
    Collector collector(lcm, service.channels());
    service.start();
    lockstep(lcm, service, collector, graph, order, 0, order.size());
    service.stop();
    return service.summary();
  };
  const ServeSummary without = run(false);
  const ServeSummary with = run(true);
  EXPECT_EQ(without.reseeds, 0);
  EXPECT_GT(with.reseeds, 0);
  EXPECT_EQ(with.batches.size(), order.size() / 50);
  EXPECT_EQ(with.batches_skipped, 0);
  for (const auto& b : with.batches) {
    EXPECT_EQ(b.reseeded, b.winner != "incremental");  // synchronous: always kept
    EXPECT_FALSE(b.reseed_rejected);
    if (b.reseeded) {
      EXPECT_LT(b.F_after_reseed, b.F_before_reseed);
    }
  }
  EXPECT_EQ(with.applied, static_cast<std::int64_t>(order.size()));
  EXPECT_LE(with.F_final, without.F_final * (1 + 1e-6));
}

// Options of a first run that journals and reseeds (no refinement on exit: the restart must
// reproduce the estimate of the last update).
ServeOptions reseedingJournalOptions(const std::string& journal, refine::BatchSolver solver,
                                     int every) {
  ServeOptions options;
  options.refine_on_exit = false;
  options.journal_path = journal;
  options.fsync_before_update = false;
  options.batch.solver = solver;
  options.batch.every = every;
  options.batch.reseed = true;
  return options;
}

// Restarts a service from `journal` (no batches of its own: the reseeds come from the journal)
// and expects the very estimate `before`, with `reseeds` reseeds replayed.
void expectRestartReproduces(const std::string& journal, const Estimate& before, int reseeds) {
  lcm::LCM lcm("memq://");
  ServeOptions options;
  options.refine_on_exit = false;
  options.journal_path = journal;
  Service service(lcm, options);
  Collector collector(lcm, service.channels());
  service.start();
  sendCommand(lcm, service, command_t::PUBLISH_FULL);
  ASSERT_TRUE(collector.waitFull(1));
  const estimate_t after = collector.fullEstimates().back();
  service.stop();
  EXPECT_EQ(service.summary().journal_reseeds, reseeds);
  EXPECT_EQ(after.ids, before.ids);
  EXPECT_EQ(after.translation, before.translation);  // bit for bit
  EXPECT_EQ(after.rotation, before.rotation);
}

TEST(LcmServeBatch, JournalRestartAfterReseedsReproducesTheEstimate) {
  const PoseGraph2 graph = noisyGraph(300, 0.2, 11);
  const std::vector<int> order = replayOrder(graph);
  const size_t half = order.size() / 2;
  const std::string journal = tempPath("journal.lcmlog");
  Estimate before;
  int reseeds = 0;
  {
    lcm::LCM lcm("memq://");
    ServeOptions options = reseedingJournalOptions(journal, refine::BatchSolver::kRtr, 40);
    options.batch.synchronous = true;
    Service service(lcm, options);
    Collector collector(lcm, service.channels());
    service.start();
    lockstep(lcm, service, collector, graph, order, 0, half);
    service.stop();
    before = service.summary().final_estimate;
    reseeds = service.summary().reseeds;
  }
  ASSERT_GT(reseeds, 0) << "no reseed happened: nothing to reproduce";
  expectRestartReproduces(journal, before, reseeds);
  std::remove(journal.c_str());
}

// Background batches finish at moments no replay can reproduce; the journal holds their reseeds,
// so a restart still reproduces the estimate bit for bit.
TEST(LcmServeBatch, JournalRestartAfterBackgroundReseedsReproducesTheEstimate) {
  const PoseGraph2 graph = noisyGraph(300, 0.2, 11);
  const std::vector<int> order = replayOrder(graph);
  const std::string journal = tempPath("background.lcmlog");
  Estimate before;
  ServeSummary first;
  {
    lcm::LCM lcm("memq://");
    Service service(lcm,
                    reseedingJournalOptions(journal, refine::BatchSolver::kLevenbergMarquardt, 10));
    Collector collector(lcm, service.channels());
    service.start();
    for (size_t k = 0; k < order.size(); ++k) {
      const auto b = edgeBytes(graph, order[k], static_cast<std::int64_t>(k) + 1);
      lcm.publish(service.channels().edges, b.data(), static_cast<unsigned>(b.size()));
      if (k % 3 == 0) {  // mixed grouping, many updates
        ASSERT_TRUE(collector.waitCovered(static_cast<std::int64_t>(k) + 1));
      }
    }
    ASSERT_TRUE(collector.waitCovered(static_cast<std::int64_t>(order.size())));
    service.stop();
    first = service.summary();
    before = first.final_estimate;
  }
  EXPECT_GT(first.batches.size(), 0u);
  int updates_during = 0;
  for (const auto& b : first.batches) updates_during += b.updates_during;
  std::cout << first.batches.size() << " batches (" << updates_during << " updates meanwhile), "
            << first.reseeds << " reseeds, " << first.batches_skipped << " skipped\n";
  expectRestartReproduces(journal, before, first.reseeds);
  std::remove(journal.c_str());
}

TEST(LcmServeBatch, CommandLineRefusesBadBatchFlags) {
  EXPECT_THROW(cli::serveCommand({"--batch", "gn"}), cli::UsageError);
  EXPECT_THROW(cli::serveCommand({"--batch-every", "5"}), cli::UsageError);
  EXPECT_THROW(cli::serveCommand({"--batch", "lm", "--batch-every", "-1"}), cli::UsageError);
  EXPECT_THROW(cli::serveCommand({"--intake-window", "0"}), cli::UsageError);
}

}  // namespace
}  // namespace arbor::serve
