// `arbor serve` after one forged message (issue 56 item 3), in-process over memq://: each forged
// case of the issue is sent before a real stream, and every real edge is still applied; a
// restart on the journal keeps nothing the forged message changed. Every wait is on a
// condition, with a generous timeout only as a failure guard.
#include <cstdint>
#include <filesystem>
#include <limits>
#include <string>
#include <vector>

#include <gtest/gtest.h>
#include <lcm/lcm-cpp.hpp>

#include "arbor_slam/io/lcm_messages.h"
#include "arbor_slam/tests/lcm_test_support.h"
#include "arbor_slam/tools/serve/serve_service.h"

namespace arbor::serve {
namespace {

using testing::Collector;
using testing::edgeBytes;
using testing::replayOrder;
using testing::streamEdge;

constexpr double kGuard = 60;  // seconds: a failure guard, never a pacing

PoseGraph2 smallGraph() { return testing::manhattanGraph(120, 4, -1, 3); }

void publish(lcm::LCM& lcm, const std::string& channel, const std::vector<std::uint8_t>& bytes) {
  lcm.publish(channel, bytes.data(), static_cast<unsigned>(bytes.size()));
}

/// Streams edges [first, last) of `order` as sender 1 (seq = position + 1); waits until the
/// estimate covers the last one.
void stream(lcm::LCM& lcm, const Service& service, Collector& collector, const PoseGraph2& graph,
            const std::vector<int>& order, size_t first, size_t last) {
  for (size_t k = first; k < last; ++k) {
    publish(lcm, service.channels().edges,
            edgeBytes(streamEdge(graph, order[k], static_cast<std::int64_t>(k) + 1)));
  }
  ASSERT_TRUE(collector.waitCovered(static_cast<std::int64_t>(last), kGuard));
}

std::vector<std::uint8_t> forgedEdge(std::int64_t sender, std::int64_t seq) {
  StreamEdge<SE2> e;
  e.sender = sender;
  e.seq = seq;
  e.from = 0;
  e.to = 1;
  return encodeMessage(makeEdgeMessage(e));
}

TEST(ServeForgery, A3DEdgeBeforeA2DStreamChangesNothingWithDim2) {
  const PoseGraph2 graph = smallGraph();
  const std::vector<int> order = replayOrder(graph);
  lcm::LCM lcm("memq://");
  ServeOptions options;
  options.dim = 2;
  options.refine_on_exit = false;
  Service service(lcm, options);
  Collector collector(lcm, service.channels());
  service.start();
  StreamEdge<SE3> e3;
  e3.sender = 1;  // even the real sender's id and first seq
  e3.seq = 1;
  e3.from = 0;
  e3.to = 1;
  publish(lcm, service.channels().edges, encodeMessage(makeEdgeMessage(e3)));
  stream(lcm, service, collector, graph, order, 0, order.size());
  service.stop();
  const ServeSummary& s = service.summary();
  EXPECT_EQ(s.applied, static_cast<std::int64_t>(order.size()));
  EXPECT_EQ(s.intake.rejected_by_reason.at("dim"), 1);
  EXPECT_EQ(s.intake.rejected, 1);
}

TEST(ServeForgery, AFarSeqIsHeldAndNeitherItNorItsGapsSurviveARestart) {
  const PoseGraph2 graph = smallGraph();
  const std::vector<int> order = replayOrder(graph);
  const size_t half = order.size() / 2;
  const std::string journal = testing::tempPath("arbor_serve_forgery", "journal.lcmlog");
  {
    lcm::LCM lcm("memq://");
    ServeOptions options;
    options.refine_on_exit = false;
    options.journal_path = journal;
    Service service(lcm, options);
    Collector collector(lcm, service.channels());
    service.start();
    // Sender 1's seq 2^62, and 2^63 − 1 (the largest, once a signed overflow of the gap count).
    publish(lcm, service.channels().edges, forgedEdge(1, std::int64_t{1} << 62));
    publish(lcm, service.channels().edges, forgedEdge(1, std::numeric_limits<std::int64_t>::max()));
    stream(lcm, service, collector, graph, order, 0, half);
    service.stop();
    const ServeSummary& s = service.summary();
    EXPECT_EQ(s.applied, static_cast<std::int64_t>(half));
    EXPECT_EQ(s.intake.gaps, 0);
    EXPECT_EQ(s.intake.held, 0);
    EXPECT_EQ(s.intake.rejected_by_reason.at("unconfirmed jump"), 2);
  }
  // The forged seqs were never journaled: the replay rebuilds sender 1's window from its real
  // edges, and the rest of its stream is applied.
  lcm::LCM lcm("memq://");
  ServeOptions options;
  options.refine_on_exit = false;
  options.journal_path = journal;
  Service service(lcm, options);
  Collector collector(lcm, service.channels());
  service.start();
  stream(lcm, service, collector, graph, order, half, order.size());
  service.stop();
  const ServeSummary& s = service.summary();
  EXPECT_EQ(s.journal_edges, static_cast<std::int64_t>(half));
  EXPECT_EQ(s.applied, static_cast<std::int64_t>(order.size()));
  EXPECT_EQ(s.intake.gaps, 0);
  EXPECT_EQ(s.intake.rejected, 0);
  std::filesystem::remove(journal);
}

TEST(ServeForgery, ARealJumpIsConfirmedJournaledAndConfirmedAgainOnReplay) {
  const PoseGraph2 graph = smallGraph();
  const std::vector<int> order = replayOrder(graph);
  const size_t half = order.size() / 2;
  const std::int64_t jump = 1000000;  // the second half after a sender restart, say
  const std::string journal = testing::tempPath("arbor_serve_forgery", "jump.lcmlog");
  double F = 0;
  {
    lcm::LCM lcm("memq://");
    ServeOptions options;
    options.refine_on_exit = false;
    options.journal_path = journal;
    Service service(lcm, options);
    Collector collector(lcm, service.channels());
    service.start();
    stream(lcm, service, collector, graph, order, 0, half);
    for (size_t k = half; k < order.size(); ++k) {
      publish(lcm, service.channels().edges,
              edgeBytes(streamEdge(graph, order[k], jump + static_cast<std::int64_t>(k))));
    }
    ASSERT_TRUE(collector.waitCovered(jump + static_cast<std::int64_t>(order.size()) - 1, kGuard));
    service.stop();
    const ServeSummary& s = service.summary();
    EXPECT_EQ(s.applied, static_cast<std::int64_t>(order.size()));
    EXPECT_EQ(s.intake.jumps_confirmed, 1);
    F = s.F_final;
  }
  lcm::LCM lcm("memq://");
  ServeOptions options;
  options.refine_on_exit = false;
  options.journal_path = journal;
  Service service(lcm, options);
  service.start();
  service.stop();
  const ServeSummary& s = service.summary();
  EXPECT_EQ(s.journal_edges, static_cast<std::int64_t>(order.size()));
  EXPECT_EQ(s.intake.jumps_confirmed, 1);
  EXPECT_EQ(s.intake.held, 0);
  EXPECT_EQ(s.F_final, F);
  std::filesystem::remove(journal);
}

TEST(ServeForgery, SixtyFourInventedSendersDoNotShutOutTheRealOne) {
  const PoseGraph2 graph = smallGraph();
  const std::vector<int> order = replayOrder(graph);
  lcm::LCM lcm("memq://");
  ServeOptions options;
  options.refine_on_exit = false;
  Service service(lcm, options);
  Collector collector(lcm, service.channels());
  service.start();
  const auto max_senders = static_cast<std::int64_t>(options.max_senders);
  for (std::int64_t sender = 1000; sender < 1000 + max_senders; ++sender) {
    publish(lcm, service.channels().edges, forgedEdge(sender, 1));
    StreamEdgeCommand c;
    c.sender = sender;
    c.seq = 1;
    c.kind = StreamEdgeCommand::Kind::kEnable;
    c.from = 0;
    c.to = 1;
    publish(lcm, service.channels().edge_commands, encodeMessage(makeEdgeCommandMessage(c)));
  }
  StreamEdgeCommand real;  // the real operator's command, after the flood
  real.sender = 1;
  real.seq = nowMicros() / 1000;  // as `arbor command` numbers it
  real.kind = StreamEdgeCommand::Kind::kEnable;
  real.from = 0;
  real.to = 1;
  publish(lcm, service.channels().edge_commands, encodeMessage(makeEdgeCommandMessage(real)));
  stream(lcm, service, collector, graph, order, 0, order.size());
  service.stop();
  const ServeSummary& s = service.summary();
  // Every real edge (and the forged ones: without a key they are indistinguishable) accepted.
  EXPECT_EQ(s.intake.rejected, 0);
  EXPECT_EQ(s.intake.accepted, static_cast<std::int64_t>(order.size()) + max_senders);
  EXPECT_EQ(s.intake.senders_evicted, 1);
  EXPECT_EQ(s.final_estimate.num_poses, graph.numPoses());
  EXPECT_EQ(s.command_intake.rejected, 0);
  EXPECT_EQ(s.command_intake.accepted, max_senders + 1);
  EXPECT_EQ(s.command_intake.senders_evicted, 1);
  EXPECT_EQ(s.commands_applied, max_senders + 1);
}

}  // namespace
}  // namespace arbor::serve
