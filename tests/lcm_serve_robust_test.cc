// `arbor serve --robust` in process over memq:// (issue 14 parts 1, 3, 6 for serve): the shared
// group-outlier file streamed one edge per update rejects exactly what `arbor replay --robust`
// rejects; edge_t's trust keeps a marked closure at weight 1 and judges marked odometry; its
// kernel is the closure's; the status' robust block and command CLOSURES' report; an old
// publisher's edge_v1_t journal replays to the same estimate.
#include <algorithm>
#include <chrono>
#include <filesystem>
#include <fstream>
#include <set>
#include <sstream>
#include <string>
#include <thread>
#include <utility>
#include <vector>

#include <gtest/gtest.h>

#include "arbor_slam/core/gnc_solver.h"
#include "arbor_slam/io/labels_file.h"
#include "arbor_slam/io/lcm_messages.h"
#include "arbor_slam/io/pose_graph_file.h"
#include "arbor_slam/tests/lcm_test_support.h"
#include "arbor_slam/tools/cli/batch_refinement.h"
#include "arbor_slam/tools/cli/cli_common.h"
#include "arbor_slam/tools/cli/replay_order.h"
#include "arbor_slam/tools/cli/replay_runner.h"
#include "arbor_slam/tools/cli/serve_command.h"
#include "arbor_slam/tools/serve/closure_report.h"
#include "arbor_slam/tools/serve/serve_service.h"

namespace arbor::serve {
namespace {

using testing::Collector;
using testing::replayOrder;
using testing::streamEdge;

using IdPair = std::pair<Key, Key>;

std::string tempPath(const std::string& name) {
  return testing::tempPath("arbor_serve_robust", name);
}

PoseGraph2 groupFile() {
  return std::get<PoseGraph2>(
      readPoseGraphFile(std::string(ARBOR_SOURCE_DIR) + "/data/manhattan_2d_group_0.1.g2o"));
}

std::set<IdPair> outliers(const std::vector<ClosureReport>& closures) {
  std::set<IdPair> out;
  for (const ClosureReport& c : closures)
    if (c.status == ClosureStatus::kOutlier) out.insert({c.from, c.to});
  return out;
}

void publishBytes(lcm::LCM& lcm, const std::string& channel, const std::vector<std::uint8_t>& b) {
  lcm.publish(channel, b.data(), static_cast<unsigned>(b.size()));
}

void sendCommand(lcm::LCM& lcm, const Service& service, std::int8_t kind,
                 const std::string& path = "") {
  command_t c;
  c.utime = 0;
  c.command = kind;
  c.path = path;
  publishBytes(lcm, service.channels().command, encodeMessage(c));
}

// Streams `edges` (already numbered 1, 2, ...) one at a time, each waited for: one update per
// edge, as `arbor replay --step edge` runs them.
void lockstep(lcm::LCM& lcm, const Service& service, Collector& collector,
              const std::vector<std::vector<std::uint8_t>>& edges) {
  for (size_t k = 0; k < edges.size(); ++k) {
    publishBytes(lcm, service.channels().edges, edges[k]);
    ASSERT_TRUE(collector.waitCovered(static_cast<std::int64_t>(k) + 1, 60)) << "edge " << k;
  }
}

std::vector<std::vector<std::uint8_t>> edgeMessages(const PoseGraph2& graph,
                                                    const std::vector<int>& order) {
  std::vector<std::vector<std::uint8_t>> out;
  for (size_t k = 0; k < order.size(); ++k)
    out.push_back(encodeMessage(
        makeEdgeMessage(streamEdge(graph, order[k], static_cast<std::int64_t>(k) + 1))));
  return out;
}

// Waits (a failure guard, not a timing assumption) until `path` exists.
bool waitForFile(const std::string& path, double timeout_s = 60) {
  const auto end = std::chrono::steady_clock::now() + std::chrono::duration<double>(timeout_s);
  while (std::chrono::steady_clock::now() < end) {
    if (std::filesystem::exists(path)) return true;
    std::this_thread::sleep_for(std::chrono::milliseconds(10));
  }
  return false;
}

TEST(LcmServeRobust, RejectsWhatReplayRejects) {
  const PoseGraph2 graph = groupFile();
  const std::vector<int> order = replayOrder(graph);
  cli::ReplaySettings settings;
  settings.robust = RobustOptions{};
  settings.batch = false;
  const cli::ReplayResult<SE2> replay = cli::runReplay(graph, settings);
  const std::set<IdPair> replay_rejected = outliers(replay.closures);
  ASSERT_FALSE(replay_rejected.empty());

  lcm::LCM lcm("memq://");
  ServeOptions options;
  options.robust = RobustOptions{};
  options.snapshot_dir = tempPath("snapshots");
  std::filesystem::create_directory(options.snapshot_dir);
  const std::string report_path = options.snapshot_dir + "/closures.txt";
  Service service(lcm, options);
  Collector collector(lcm, service.channels());
  service.start();
  lockstep(lcm, service, collector, edgeMessages(graph, order));

  // The status' robust block, of the last update.
  sendCommand(lcm, service, command_t::STATUS);
  ASSERT_TRUE(collector.waitStatus(
      [&](const status_t& s) { return s.applied == static_cast<std::int64_t>(order.size()); }, 60));
  const status_t live = collector.status();
  EXPECT_TRUE(live.robust);
  EXPECT_GT(live.closures_outlier, 0);
  EXPECT_EQ(live.closures_total, live.closures_inlier + live.closures_outlier +
                                     live.closures_trusted + live.closures_excluded);
  EXPECT_DOUBLE_EQ(live.inlier_threshold, chiSquareThreshold(0.99, 3));

  // Command CLOSURES: every closure `i j weight status`, as the smoother holds them now.
  sendCommand(lcm, service, command_t::CLOSURES, "closures.txt");
  ASSERT_TRUE(waitForFile(report_path));
  std::ifstream report(report_path);
  int lines = 0, rejected_in_report = 0;
  for (std::string line; std::getline(report, line); ++lines) {
    std::istringstream fields(line);
    Key i = -1, j = -1;
    double w = -1;
    std::string status;
    ASSERT_TRUE(fields >> i >> j >> w >> status) << line;
    EXPECT_TRUE(w >= 0 && w <= 1) << line;
    EXPECT_TRUE(status == "inlier" || status == "outlier" || status == "trusted") << line;
    rejected_in_report += status == "outlier";
  }
  EXPECT_EQ(lines, live.closures_total);
  EXPECT_EQ(rejected_in_report, live.closures_outlier);

  service.stop();  // refines: finalize(), as the replay's final pass
  const ServeSummary& s = service.summary();
  EXPECT_EQ(outliers(s.closures), replay_rejected);
  ASSERT_EQ(s.closures.size(), replay.closures.size());
  for (size_t k = 0; k < s.closures.size(); ++k) {
    EXPECT_EQ(s.closures[k].from, replay.closures[k].from);
    EXPECT_EQ(s.closures[k].to, replay.closures[k].to);
    EXPECT_EQ(s.closures[k].weight, replay.closures[k].weight) << k;
  }
  // --rejected-out's file: the same set.
  const std::string rejected_path = tempPath("rejected.txt");
  writeRejectedEdges(rejected_path, s.closures);
  const std::vector<LabelPair> written = readLabelsFile(rejected_path);
  EXPECT_EQ(std::set<IdPair>(written.begin(), written.end()), replay_rejected);
  std::remove(rejected_path.c_str());
  std::filesystem::remove_all(options.snapshot_dir);
}

// CLOSURES follows SNAPSHOT's rules: a plain name inside --snapshot-dir, refused without it and
// for any other name, counted by reason.
TEST(LcmServeRobust, ClosuresFollowTheSnapshotDirRules) {
  const PoseGraph2 graph = testing::manhattanGraph(40, 4, -1, 2);
  const std::vector<int> order = replayOrder(graph);
  const std::string dir = tempPath("closures_dir");
  std::filesystem::create_directory(dir);
  {
    lcm::LCM lcm("memq://");
    ServeOptions options;
    options.robust = RobustOptions{};  // no --snapshot-dir
    Service service(lcm, options);
    Collector collector(lcm, service.channels());
    service.start();
    lockstep(lcm, service, collector, edgeMessages(graph, order));
    sendCommand(lcm, service, command_t::CLOSURES, "closures.txt");
    sendCommand(lcm, service, command_t::STATUS);
    ASSERT_TRUE(collector.waitStatus([](const status_t& s) { return s.control_refused > 0; }, 60));
    service.stop();
    EXPECT_EQ(service.summary().control_refused.count("closures no dir"), 1u);
  }
  lcm::LCM lcm("memq://");
  ServeOptions options;
  options.robust = RobustOptions{};
  options.snapshot_dir = dir;
  Service service(lcm, options);
  Collector collector(lcm, service.channels());
  service.start();
  lockstep(lcm, service, collector, edgeMessages(graph, order));
  sendCommand(lcm, service, command_t::CLOSURES, "../outside.txt");  // refused: not a plain name
  sendCommand(lcm, service, command_t::CLOSURES, "closures.txt");    // after it, in order
  ASSERT_TRUE(waitForFile(dir + "/closures.txt"));
  service.stop();
  EXPECT_EQ(service.summary().control_refused.count("closures name"), 1u);
  EXPECT_FALSE(std::filesystem::exists(std::filesystem::path(dir).parent_path() / "outside.txt"));
  std::filesystem::remove_all(dir);
}

// A 2D Manhattan world with a false closure and a false second odometry edge planted. Unmarked,
// the closure is rejected and the odometry not judged; with the closure marked `trusted` it
// keeps weight 1, with the odometry marked `robust` it is judged (and rejected), and a true
// closure sent with KERNEL_CAUCHY is judged by Cauchy.
TEST(LcmServeRobust, TrustAndKernelPerEdge) {
  PoseGraph2 graph = testing::manhattanGraph(120, 4, -1, 5);
  int closure = -1;  // a true loop closure between two poses known when it comes
  for (int e = 0; e < static_cast<int>(graph.edges.size()); ++e) {
    const auto& edge = graph.edges[e];
    if (std::abs(edge.j - edge.i) > 1 && std::min(edge.i, edge.j) > 5) {
      closure = e;
      break;
    }
  }
  ASSERT_GE(closure, 0);
  RelativePoseEdge<SE2> wrong = graph.edges.back();
  wrong.i = 10;
  wrong.j = 90;
  wrong.measurement = SE2(0.5, 0.2, 0.1);
  graph.edges.push_back(wrong);
  const int false_closure = static_cast<int>(graph.edges.size()) - 1;
  wrong.i = 60;
  wrong.j = 61;
  wrong.measurement = SE2(3.0, -2.0, 1.0);
  graph.edges.push_back(wrong);  // after the true 60 -> 61 in replay order: both poses known
  const int false_odometry = static_cast<int>(graph.edges.size()) - 1;
  const std::vector<int> order = replayOrder(graph);

  auto run = [&](bool mark) {
    lcm::LCM lcm("memq://");
    ServeOptions options;
    options.robust = RobustOptions{};
    Service service(lcm, options);
    Collector collector(lcm, service.channels());
    service.start();
    std::vector<std::vector<std::uint8_t>> edges;
    for (size_t k = 0; k < order.size(); ++k) {
      StreamEdge<SE2> e = streamEdge(graph, order[k], static_cast<std::int64_t>(k) + 1);
      if (mark && order[k] == false_closure) e.trust = EdgeTrust::kTrusted;
      if (mark && order[k] == false_odometry) e.trust = EdgeTrust::kRobust;
      if (mark && order[k] == closure) e.kernel = KernelKind::kCauchy;
      edges.push_back(encodeMessage(makeEdgeMessage(e)));
    }
    lockstep(lcm, service, collector, edges);
    service.stop();
    return service.summary().closures;
  };
  auto find = [&](const std::vector<ClosureReport>& closures, int e) {
    const Key i = graph.ids[graph.edges[e].i], j = graph.ids[graph.edges[e].j];
    for (const ClosureReport& c : closures)
      if (c.from == i && c.to == j) return &c;
    return static_cast<const ClosureReport*>(nullptr);
  };

  const std::vector<ClosureReport> unmarked = run(false);
  ASSERT_NE(find(unmarked, false_closure), nullptr);
  EXPECT_EQ(find(unmarked, false_closure)->status, ClosureStatus::kOutlier);
  EXPECT_EQ(find(unmarked, false_odometry), nullptr);  // odometry is not judged by default
  ASSERT_NE(find(unmarked, closure), nullptr);
  EXPECT_EQ(find(unmarked, closure)->kernel, KernelKind::kTruncatedLeastSquares);

  const std::vector<ClosureReport> marked = run(true);
  const ClosureReport* trusted = find(marked, false_closure);
  ASSERT_NE(trusted, nullptr);
  EXPECT_EQ(trusted->status, ClosureStatus::kTrusted);
  EXPECT_EQ(trusted->weight, 1.0);
  const ClosureReport* judged = find(marked, false_odometry);
  ASSERT_NE(judged, nullptr);
  EXPECT_EQ(judged->status, ClosureStatus::kOutlier);
  ASSERT_NE(find(marked, closure), nullptr);
  EXPECT_EQ(find(marked, closure)->kernel, KernelKind::kCauchy);
}

// A publisher built before trust and kernel sends edge_v1_t: served as trust and kernel
// DEFAULT, journaled as received, and a restart replays that journal to the same estimate.
TEST(LcmServeRobust, OldEdgeV1JournalReplays) {
  const PoseGraph2 graph = testing::manhattanGraph(80, 4, -1, 7);
  const std::vector<int> order = replayOrder(graph);
  const std::string journal = tempPath("v1.lcmlog");
  Estimate first;
  {
    lcm::LCM lcm("memq://");
    ServeOptions options;
    options.journal_path = journal;
    options.refine_on_exit = false;
    options.robust = RobustOptions{};
    Service service(lcm, options);
    Collector collector(lcm, service.channels());
    service.start();
    std::vector<std::vector<std::uint8_t>> edges;
    for (size_t k = 0; k < order.size(); ++k)
      edges.push_back(encodeMessage(
          makeEdgeV1Message(streamEdge(graph, order[k], static_cast<std::int64_t>(k) + 1))));
    lockstep(lcm, service, collector, edges);
    service.stop();
    EXPECT_EQ(service.summary().applied, static_cast<std::int64_t>(order.size()));
    EXPECT_EQ(service.summary().intake.rejected, 0);
    first = service.summary().final_estimate;
  }
  {
    lcm::LCM lcm("memq://");
    ServeOptions options;
    options.journal_path = journal;
    options.refine_on_exit = false;
    options.robust = RobustOptions{};
    Service service(lcm, options);
    service.start();
    service.stop();
    const ServeSummary& s = service.summary();
    EXPECT_EQ(s.journal_edges, static_cast<std::int64_t>(order.size()));
    ASSERT_EQ(s.final_estimate.num_poses, first.num_poses);
    for (int k = 0; k < first.num_poses; ++k) {
      EXPECT_EQ(s.final_estimate.ids[k], first.ids[k]);
      for (int c = 0; c < 3; ++c)
        EXPECT_EQ(s.final_estimate.translation[k][c], first.translation[k][c]) << k;
    }
  }
  std::remove(journal.c_str());
}

TEST(LcmServeRobust, CommandLineTakesTheReplaysRobustFlags) {
  const auto line = cli::parseServeCommandLine(
      {"--robust", "--kernel", "gm", "--inlier-threshold", "2", "--rejected-out", "r.txt"});
  ASSERT_TRUE(line.has_value());
  ASSERT_TRUE(line->options.robust.has_value());
  EXPECT_EQ(line->options.robust->kernel, KernelKind::kGemanMcClure);
  EXPECT_EQ(line->options.robust->threshold, 2.0);
  EXPECT_EQ(line->robust.rejected_out, "r.txt");
  EXPECT_FALSE(cli::parseServeCommandLine({})->options.robust.has_value());
  for (const std::vector<std::string>& bad :
       std::vector<std::vector<std::string>>{{"--kernel", "tls"},
                                             {"--rejected-out", "r.txt"},
                                             {"--robust", "--kernel", "welsch"},
                                             {"--robust", "--inlier-threshold", "auto"},
                                             {"--robust", "--inlier-threshold", "-1"}}) {
    EXPECT_THROW(cli::parseServeCommandLine(bad), cli::UsageError) << bad[0];
  }
}

// The robust periodic batch (tools/refine/batch_refiner.h) in the replay loop on the group file:
// every run is GNC (and for rtr the staircase on its inliers), keep-best by Σρ never ends above
// the online estimate's Σρ, and a kept reseed lowered the smoother's Σρ.
TEST(RobustBatch, ReplayBatchesNeverWorseInRobustCostThanOnline) {
  const PoseGraph2 graph = groupFile();
  cli::ReplaySettings settings;
  settings.robust = RobustOptions{};
  // Ω at its word: the periodic batches run GNC at the c² in use, here the χ² quantile (with the
  // estimated noise scale it is tail_factor·c²·σ̂², σ̂² moving with the closures); the final
  // one, after finalize(), from the smoother's classification at the bound it keeps a settled
  // inlier within, recheck_margin times that.
  settings.robust->scale = NoiseScale::kGiven;
  for (const refine::BatchSolver solver :
       {refine::BatchSolver::kLevenbergMarquardt, refine::BatchSolver::kRtr}) {
    cli::BatchLoopSettings loop;
    loop.solver = solver;
    loop.every = 300;
    loop.reseed = true;
    loop.synchronous = true;  // each batch at its snapshot: the same runs on any machine
    const cli::LoopResult<SE2> r = cli::runReplayWithBatches(graph, settings, loop);
    ASSERT_GE(r.batches.size(), 5u);
    int reseeded = 0;
    for (const refine::BatchRun& b : r.batches) {
      SCOPED_TRACE("update " + std::to_string(b.update) + " " + refine::toString(solver));
      EXPECT_TRUE(b.robust);
      EXPECT_GT(b.judged, 0);
      EXPECT_DOUBLE_EQ(b.threshold, (b.final_run ? robust_constants::kRecheckMargin : 1.0) *
                                        chiSquareThreshold(0.99, 3));
      const double winner = b.winner == "incremental" ? b.F_incremental
                            : b.winner == "gnc"       ? b.F_lm
                                                      : b.F_rtr;
      EXPECT_TRUE(b.winner == "incremental" || b.winner == "gnc" ||
                  (b.winner == "rtr" && solver == refine::BatchSolver::kRtr))
          << b.winner;
      EXPECT_LE(winner, b.F_incremental);  // Σρ: never worse than the online estimate
      EXPECT_LE(b.F_lm, b.F_incremental * (1 + 1e-9));
      if (solver == refine::BatchSolver::kRtr && b.rtr_skipped.empty()) {
        EXPECT_GT(b.rank, 0);
        EXPECT_TRUE(b.certified);  // of the inlier problem
      }
      if (b.reseeded && !b.final_run) {
        ++reseeded;
        EXPECT_LT(b.F_after_reseed, b.F_before_reseed);
      }
    }
    EXPECT_GT(reseeded, 0);
    // The reseeds keep the false closures out: recall on the labels stays complete.
    const std::vector<LabelPair> labels =
        readLabelsFile(std::string(ARBOR_SOURCE_DIR) + "/data/manhattan_2d_group_0.1.labels");
    const std::set<IdPair> rejected = outliers(r.replay.closures);
    for (const LabelPair& p : labels)
      EXPECT_EQ(rejected.count(p), 1u) << p.first << " " << p.second;
  }
}

// serve --robust --batch rtr --batch-every N --reseed, journaled: a restart from the journal (the
// reseeds replayed from their records, each followed by the re-check of every settled closure)
// reproduces the estimate bit for bit and the same classification.
TEST(RobustBatch, ServeReseedJournalRestartReproduces) {
  const PoseGraph2 graph = groupFile();
  std::vector<int> order = replayOrder(graph);
  order.resize(1200);
  const std::string journal = tempPath("reseed.lcmlog");
  Estimate before;
  std::vector<ClosureReport> closures;
  int reseeds = 0;
  {
    lcm::LCM lcm("memq://");
    ServeOptions options;
    options.refine_on_exit = false;
    options.journal_path = journal;
    options.fsync_before_update = false;
    options.robust = RobustOptions{};
    options.batch.solver = refine::BatchSolver::kRtr;
    options.batch.every = 250;
    options.batch.reseed = true;
    options.batch.synchronous = true;
    Service service(lcm, options);
    Collector collector(lcm, service.channels());
    service.start();
    lockstep(lcm, service, collector, edgeMessages(graph, order));
    service.stop();
    before = service.summary().final_estimate;
    closures = service.summary().closures;
    reseeds = service.summary().reseeds;
    for (const refine::BatchRun& b : service.summary().batches) {
      EXPECT_TRUE(b.robust);
      EXPECT_LE(b.winner == "incremental" ? b.F_incremental
                : b.winner == "gnc"       ? b.F_lm
                                          : b.F_rtr,
                b.F_incremental);
    }
  }
  ASSERT_GT(reseeds, 0) << "no reseed happened: nothing to reproduce";
  lcm::LCM lcm("memq://");
  ServeOptions options;
  options.refine_on_exit = false;
  options.journal_path = journal;
  options.robust = RobustOptions{};
  Service service(lcm, options);
  service.start();
  service.stop();
  const ServeSummary& s = service.summary();
  EXPECT_EQ(s.journal_reseeds, reseeds);
  EXPECT_EQ(s.final_estimate.ids, before.ids);
  EXPECT_EQ(s.final_estimate.translation, before.translation);  // bit for bit
  EXPECT_EQ(s.final_estimate.rotation, before.rotation);
  ASSERT_EQ(s.closures.size(), closures.size());
  for (size_t k = 0; k < closures.size(); ++k) EXPECT_EQ(s.closures[k].weight, closures[k].weight);
  std::remove(journal.c_str());
}

}  // namespace
}  // namespace arbor::serve
