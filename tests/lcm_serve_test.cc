// arbor serve in process over memq:// (tools/serve/serve_service.h): the stream gives the same
// estimate as replay-style feeding, a burst is fully applied in few updates, bad messages are
// counted by reason while good ones keep being applied, gaps are reported, commands work, and
// a restart from the journal reproduces the estimate exactly; priors (prior_t on ARBOR_PRIORS)
// streamed with the edges give the estimate of an OnlineSmoother fed directly, are journaled
// and replayed in their order among the edges, and hostile ones are refused with their reason.
#include <algorithm>
#include <chrono>
#include <condition_variable>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <functional>
#include <limits>
#include <map>
#include <mutex>
#include <set>
#include <sstream>
#include <string>
#include <thread>

#include <gtest/gtest.h>
#include <unistd.h>

#include "arbor_slam/bayestree/online_smoother.h"
#include "arbor_slam/io/lcm_journal.h"
#include "arbor_slam/io/lcm_messages.h"
#include "arbor_slam/io/pose_graph_file.h"
#include "arbor_slam/tests/lcm_test_support.h"
#include "arbor_slam/tools/cli/replay_order.h"
#include "arbor_slam/tools/generator/graph_generator.h"
#include "arbor_slam/tools/serve/lcm_mapping.h"
#include "arbor_slam/tools/serve/serve_service.h"

namespace arbor::serve {
namespace {

using Clock = std::chrono::steady_clock;

using testing::Collector;
using testing::edgeBytes;
using testing::finalizedReplay;
using testing::replayOrder;
using testing::streamEdge;

PoseGraph2 smallGraph() { return testing::manhattanGraph(150, 4, -1, 3); }  // default noise

template <class Message>  // estimate_t or Estimate
void expectSamePoses(const Message& m, const std::map<Key, SE2>& expected, double tol) {
  ASSERT_EQ(m.num_poses, static_cast<int>(expected.size()));
  for (int k = 0; k < m.num_poses; ++k) {
    const SE2& e = expected.at(m.ids[k]);
    double t[3], r[4];
    poseToFields(e, t, r);  // compared as the fields on the wire
    EXPECT_NEAR(m.translation[k][0], t[0], tol) << "pose " << m.ids[k];
    EXPECT_NEAR(m.translation[k][1], t[1], tol) << "pose " << m.ids[k];
    EXPECT_NEAR(m.rotation[k][0], r[0], tol) << "pose " << m.ids[k];
  }
}

std::string tempJournal(const std::string& name) {
  return testing::tempPath("arbor_lcm_serve", name);
}

// Publishes edge order[k] of `graph` to the service, as the k-th of the stream (seq k + 1);
// returns the bytes sent.
std::vector<std::uint8_t> publishInOrder(lcm::LCM& lcm, const Service& service,
                                         const PoseGraph2& graph, const std::vector<int>& order,
                                         size_t k) {
  const auto bytes = edgeBytes(graph, order[k], static_cast<std::int64_t>(k) + 1);
  lcm.publish(service.channels().edges, bytes.data(), static_cast<unsigned>(bytes.size()));
  return bytes;
}

TEST(EdgeIntake, SeqGapsDuplicatesReuseDimAndRevoke) {
  const PoseGraph2 graph = smallGraph();
  EdgeIntake intake;
  auto bytes = [&](std::int64_t seq, std::int64_t sender = 1) {
    return edgeBytes(streamEdge(graph, 0, seq, sender));
  };
  auto admit = [&](const std::vector<std::uint8_t>& b) {
    return intake.admit(b.data(), static_cast<int>(b.size()));
  };
  EXPECT_EQ(admit(bytes(1)).verdict, Intake::kAccepted);
  EXPECT_EQ(intake.dim(), 2);
  EXPECT_EQ(admit(bytes(1)).verdict, Intake::kDuplicate);
  const IntakeResult jump = admit(bytes(5));
  EXPECT_EQ(jump.verdict, Intake::kAccepted);
  EXPECT_EQ(jump.skipped, 3);
  EXPECT_EQ(intake.counts().gaps, 3);
  EXPECT_EQ(admit(bytes(3)).verdict, Intake::kAccepted);  // late: fills one
  EXPECT_EQ(intake.counts().gaps, 2);
  EXPECT_EQ(admit(bytes(2, 7)).skipped, 1);  // a new sender starting at 2 missed seq 1
  auto other = makeEdgeMessage(streamEdge(graph, 1, 5));
  const auto reused = encodeMessage(other);
  const IntakeResult r = admit(reused);
  EXPECT_EQ(r.verdict, Intake::kRejected);
  EXPECT_EQ(r.reason, "seq reused");
  StreamEdge<SE3> e3;
  e3.seq = 9;
  e3.from = 0;
  e3.to = 1;
  EXPECT_EQ(admit(encodeMessage(makeEdgeMessage(e3))).reason, "dim");
  const IntakeResult six = admit(bytes(6));
  intake.revoke(six, "journal");
  EXPECT_EQ(admit(bytes(6)).verdict, Intake::kAccepted);  // may be sent again
  const IntakeCounts& c = intake.counts();
  EXPECT_EQ(c.received, 9);
  EXPECT_EQ(c.accepted, 5);
  EXPECT_EQ(c.duplicates, 1);
  EXPECT_EQ(c.rejected, 3);
  EXPECT_EQ(c.rejected_by_reason.at("journal"), 1);
  EXPECT_EQ(c.gaps, 3);
}

TEST(EdgeIntake, WindowDropsDuplicatesExactlyAndRefusesStaleSeqs) {
  const PoseGraph2 graph = smallGraph();
  const std::int64_t w = 8;
  EdgeIntake intake(0, w);
  auto admit = [&](std::int64_t seq, int edge = 0) {
    const auto b = edgeBytes(streamEdge(graph, edge, seq));
    return intake.admit(b.data(), static_cast<int>(b.size()));
  };
  // Out of order within the window: each seq accepted once, then a duplicate.
  for (std::int64_t seq : {5, 2, 4, 1, 3}) EXPECT_EQ(admit(seq).verdict, Intake::kAccepted) << seq;
  for (std::int64_t seq = 1; seq <= 5; ++seq) EXPECT_EQ(admit(seq).verdict, Intake::kDuplicate);
  EXPECT_EQ(intake.counts().gaps, 0);
  // Jump to 18..20 (beyond the jump limit 7: held until the run confirms it): the window is
  // now 13..20.
  EXPECT_EQ(admit(18).verdict, Intake::kHeld);
  EXPECT_EQ(admit(19).verdict, Intake::kHeld);
  EXPECT_EQ(admit(20).skipped, 12);
  EXPECT_EQ(admit(13).verdict, Intake::kAccepted);  // the oldest seq in the window, late
  EXPECT_EQ(admit(13).verdict, Intake::kDuplicate);
  EXPECT_EQ(admit(13, 1).reason, "seq reused");
  const IntakeResult below = admit(12);  // never received, but below the window
  EXPECT_EQ(below.verdict, Intake::kRejected);
  EXPECT_EQ(below.reason, "stale");
  EXPECT_EQ(admit(3).reason, "stale");  // received long ago: not a duplicate we can prove
  EXPECT_EQ(admit(20).verdict, Intake::kDuplicate);
  const IntakeCounts& c = intake.counts();
  EXPECT_EQ(c.accepted, 9);
  EXPECT_EQ(c.duplicates, 7);
  EXPECT_EQ(c.rejected_by_reason.at("stale"), 2);
  EXPECT_EQ(c.gaps, 11);  // 6..17 skipped, 13 filled; 12 stays missing
  EXPECT_THROW(EdgeIntake(0, 0), std::invalid_argument);
}

TEST(EdgeIntake, SeqTableStaysWithinTheWindow) {
  const PoseGraph2 graph = smallGraph();
  const std::int64_t w = 64;
  EdgeIntake intake(0, w);
  auto admit = [&](std::int64_t seq, std::int64_t sender = 1) {
    const auto b = edgeBytes(streamEdge(graph, 0, seq, sender));
    return intake.admit(b.data(), static_cast<int>(b.size()));
  };
  std::size_t most = 0;
  for (std::int64_t seq = 1; seq <= 10 * w; ++seq) {
    ASSERT_EQ(admit(seq).verdict, Intake::kAccepted) << seq;
    most = std::max(most, intake.trackedSeqs(1));
  }
  EXPECT_LE(most, static_cast<std::size_t>(w));
  EXPECT_EQ(admit(10 * w - w + 1).verdict, Intake::kDuplicate);  // oldest in the window
  EXPECT_EQ(admit(10 * w - w).reason, "stale");
  // The default window: a sender jumping far ahead holds at most that many slots.
  EdgeIntake wide;
  const auto first = edgeBytes(streamEdge(graph, 0, 1, 2));
  EXPECT_EQ(wide.admit(first.data(), static_cast<int>(first.size())).verdict, Intake::kAccepted);
  IntakeResult far;
  for (int k = 0; k < EdgeIntake::kConfirmRun; ++k) {  // a jump, confirmed by its run
    const auto b = edgeBytes(streamEdge(graph, 0, 10 * EdgeIntake::kDefaultWindow + k, 2));
    far = wide.admit(b.data(), static_cast<int>(b.size()));
  }
  EXPECT_EQ(far.verdict, Intake::kAccepted);
  EXPECT_LE(wide.trackedSeqs(2), static_cast<std::size_t>(EdgeIntake::kDefaultWindow));
  EXPECT_EQ(wide.admit(first.data(), static_cast<int>(first.size())).reason, "stale");
}

TEST(LcmServe, LockstepStreamEqualsReplayFeeding) {
  const PoseGraph2 graph = smallGraph();
  const std::vector<int> order = replayOrder(graph);
  lcm::LCM lcm("memq://");
  ASSERT_TRUE(lcm.good());
  ServeOptions options;
  options.refine_on_exit = false;
  Service service(lcm, options);
  Collector collector(lcm, service.channels());
  service.start();
  // One edge at a time, each waited for: one update per edge, as `arbor replay --step edge`.
  OnlineSmoother2 reference;
  for (size_t k = 0; k < order.size(); ++k) {
    const auto bytes = publishInOrder(lcm, service, graph, order, k);
    ASSERT_TRUE(collector.waitCovered(static_cast<std::int64_t>(k) + 1)) << "edge " << k;
    // The reference gets exactly what went over the wire.
    const EdgeDecoding d = decodeEdge(bytes.data(), static_cast<int>(bytes.size()));
    const auto& e = std::get<StreamEdge<SE2>>(d.edge);
    reference.addEdge(e.from, e.to, e.z, e.omega);
    reference.update();
  }
  service.stop();
  const ServeSummary& s = service.summary();
  EXPECT_EQ(s.applied, static_cast<std::int64_t>(order.size()));
  EXPECT_EQ(s.updates, static_cast<std::int64_t>(order.size()));
  EXPECT_EQ(s.intake.rejected, 0);
  EXPECT_EQ(s.intake.gaps, 0);
  // Same inputs, same grouping: the very same estimate.
  expectSamePoses(s.final_estimate, reference.estimates(), 0.0);
  // One estimate per update (the final one of stop() is not dispatched: on memq the service's
  // receive thread is the only one handling, and it has stopped).
  EXPECT_EQ(collector.estimates(), static_cast<int>(order.size()));

  // And the same as replay of the file's own values (no LCM round trip), after finalize.
  const OnlineSmoother2 replay = finalizedReplay(graph, order);
  reference.finalize();
  EXPECT_NEAR(reference.smoother().objective(), replay.smoother().objective(),
              1e-9 * replay.smoother().objective());
}

// What a udpm receiver reassembles for serve (Channels::received(), serve_command.cc) is exactly
// what the service subscribes to: a channel left out is never heard over udpm (the publishers'
// resend answers were).
TEST(LcmServe, TheUdpmReceiversChannelsAreTheServicesSubscriptions) {
  lcm::LCM lcm("memq://");
  ASSERT_TRUE(lcm.good());
  ServeOptions options;
  options.refine_on_exit = false;
  options.channel_prefix = "R1_";
  Service service(lcm, options);
  service.start();
  const std::vector<std::string> subscribed = service.subscribedChannels();
  service.stop();
  const std::set<std::string> received = service.channels().received();
  EXPECT_EQ(std::set<std::string>(subscribed.begin(), subscribed.end()), received);
  EXPECT_EQ(received.count("R1_ARBOR_RESEND_WINDOW"), 1u);
}

TEST(LcmServe, BurstIsFullyAppliedInFewerUpdatesAndMatchesReplay) {
  const PoseGraph2 graph = smallGraph();
  const std::vector<int> order = replayOrder(graph);
  lcm::LCM lcm("memq://");
  ServeOptions options;  // refine on exit, as replay finalizes
  Service service(lcm, options);
  Collector collector(lcm, service.channels());
  service.start();
  for (size_t k = 0; k < order.size(); ++k) {
    publishInOrder(lcm, service, graph, order, k);
  }
  ASSERT_TRUE(collector.waitCovered(static_cast<std::int64_t>(order.size())));
  service.stop();
  const ServeSummary& s = service.summary();
  EXPECT_EQ(s.intake.received, static_cast<std::int64_t>(order.size()));
  EXPECT_EQ(s.applied, static_cast<std::int64_t>(order.size()));
  EXPECT_LT(s.updates, static_cast<std::int64_t>(order.size()));  // batched while behind
  EXPECT_EQ(s.final_estimate.num_poses, graph.numPoses());

  const OnlineSmoother2 replay = finalizedReplay(graph, order);
  const double F = replay.smoother().objective();
  EXPECT_NEAR(s.F_final, F, 1e-9 * F);
  // F agrees to 1e-9 relative; poses then agree to about the square root of that (flat
  // directions of the objective).
  expectSamePoses(s.final_estimate, replay.estimates(), 1e-4);
}

TEST(LcmServe, BadMessagesAreCountedWhileGoodOnesAreApplied) {
  const PoseGraph2 graph = smallGraph();
  const std::vector<int> order = replayOrder(graph);
  lcm::LCM lcm("memq://");
  std::ostringstream log;
  ServeOptions options;
  options.refine_on_exit = false;
  options.log = &log;
  options.log_period = std::chrono::milliseconds(0);  // every line, for the assertions on them
  Service service(lcm, options);
  Collector collector(lcm, service.channels());
  service.start();
  const std::string ch = service.channels().edges;
  auto send = [&](const std::vector<std::uint8_t>& b) {
    lcm.publish(ch, b.data(), static_cast<unsigned>(b.size()));
  };
  const double nan = std::numeric_limits<double>::quiet_NaN();
  std::map<std::string, int> expected;
  for (size_t k = 0; k < order.size(); ++k) {
    const std::int64_t seq = static_cast<std::int64_t>(k) + 1;
    const StreamEdge<SE2> good = streamEdge(graph, order[k], seq);
    const auto bytes = edgeBytes(good);
    send(bytes);
    switch (k % 12) {
      case 1: {  // truncated
        send(std::vector<std::uint8_t>(bytes.begin(), bytes.begin() + bytes.size() / 2));
        ++expected["truncated"];
        break;
      }
      case 2: {  // another type on the edge channel
        command_t c;
        c.command = command_t::STATUS;
        send(encodeMessage(c));
        ++expected["type hash"];
        break;
      }
      case 3: {
        edge_t m = makeEdgeMessage(good);
        m.seq = 100000 + static_cast<std::int64_t>(k);
        m.sender = 2;
        m.translation[1] = nan;
        send(encodeMessage(m));
        ++expected["not finite"];
        break;
      }
      case 4: {
        edge_t m = makeEdgeMessage(good);
        m.sender = 3;
        m.information[0] = -m.information[0];
        send(encodeMessage(m));
        ++expected["information"];
        break;
      }
      case 5: {
        edge_t m = makeEdgeMessage(good);
        m.sender = 3;
        m.to_id = m.from_id;
        send(encodeMessage(m));
        ++expected["self-loop"];
        break;
      }
      case 6: {  // a 3D edge on this 2D stream
        StreamEdge<SE3> e3;
        e3.sender = 4;
        e3.seq = seq;
        e3.from = 0;
        e3.to = 1;
        send(encodeMessage(makeEdgeMessage(e3)));
        ++expected["dim"];
        break;
      }
      case 7:  // an exact duplicate: dropped, not rejected
        send(bytes);
        break;
      case 8: {  // the same seq with other contents
        edge_t m = makeEdgeMessage(good);
        m.translation[0] += 1;
        send(encodeMessage(m));
        ++expected["seq reused"];
        break;
      }
      default:
        break;
    }
  }
  ASSERT_TRUE(collector.waitCovered(static_cast<std::int64_t>(order.size())));
  service.stop();
  const ServeSummary& s = service.summary();
  EXPECT_EQ(s.applied, static_cast<std::int64_t>(order.size()));
  EXPECT_EQ(s.intake.accepted, static_cast<std::int64_t>(order.size()));
  int total = 0;
  for (const auto& [reason, n] : expected) {
    EXPECT_EQ(
        s.intake.rejected_by_reason.count(reason) ? s.intake.rejected_by_reason.at(reason) : 0, n)
        << reason;
    total += n;
  }
  EXPECT_EQ(s.intake.rejected, total);
  EXPECT_EQ(s.intake.duplicates, static_cast<std::int64_t>((order.size() + 4) / 12));
  EXPECT_EQ(s.intake.gaps, 0);
  EXPECT_NE(log.str().find("rejected edge"), std::string::npos);
  EXPECT_NE(log.str().find("information matrix"), std::string::npos) << log.str();
  EXPECT_EQ(s.final_estimate.num_poses, graph.numPoses());
}

TEST(LcmServe, GapsAreReportedAndFilledByLateEdges) {
  const PoseGraph2 graph = smallGraph();
  const std::vector<int> order = replayOrder(graph);
  lcm::LCM lcm("memq://");
  ServeOptions options;
  options.refine_on_exit = false;
  Service service(lcm, options);
  Collector collector(lcm, service.channels());
  service.start();
  for (size_t k = 0; k < 10; ++k) publishInOrder(lcm, service, graph, order, k);
  // seq 11..13 missing
  for (size_t k = 13; k < 20; ++k) publishInOrder(lcm, service, graph, order, k);
  ASSERT_TRUE(collector.waitCovered(20));
  EXPECT_EQ(service.status().gaps, 3);
  for (size_t k = 10; k < 13; ++k) publishInOrder(lcm, service, graph, order, k);
  command_t c;
  c.command = command_t::STATUS;
  const auto cb = encodeMessage(c);
  lcm.publish(service.channels().command, cb.data(), static_cast<unsigned>(cb.size()));
  EXPECT_TRUE(
      collector.waitStatus([](const status_t& s) { return s.applied == 20 && s.gaps == 0; }));
  service.stop();
  EXPECT_EQ(service.summary().intake.gaps, 0);
  EXPECT_EQ(service.summary().applied, 20);
}

// Gaps per sender: counted in the intake's sender tables (a skip adds, a late edge or a revoke
// moves them), summing to the stream's gaps; status_t lists the 16 senders with the most.
TEST(EdgeIntake, GapsPerSenderSumToTheStreamsGaps) {
  const PoseGraph2 graph = smallGraph();
  EdgeIntake intake;
  const auto send = [&](std::int64_t sender, std::int64_t seq) {
    const auto bytes = edgeBytes(streamEdge(graph, 0, seq, sender));
    return intake.admit(bytes.data(), static_cast<int>(bytes.size()));
  };
  for (std::int64_t seq : {1, 2, 5}) send(1, seq);   // 3 and 4 missing
  for (std::int64_t seq : {1, 4, 10}) send(2, seq);  // 2, 3, 5..9 missing
  for (std::int64_t seq : {1, 2, 3}) send(3, seq);   // none missing
  EXPECT_EQ(send(1, 3).verdict, Intake::kAccepted);  // late: fills one of sender 1's
  const IntakeResult revoked = send(3, 4);
  intake.revoke(revoked, "journal");  // taken back: a gap of sender 3's
  using Gaps = std::vector<std::pair<std::int64_t, std::int64_t>>;
  EXPECT_EQ(intake.gapsBySender(EdgeIntake::Kind::kEdge), (Gaps{{1, 1}, {2, 7}, {3, 1}}));
  EXPECT_EQ(intake.counts().gaps, 9);
  EXPECT_TRUE(intake.gapsBySender(EdgeIntake::Kind::kPrior).empty());

  // status_t: most first, ties by sender, at most 16; the rest only in the total.
  CoreStatus core;
  for (std::int64_t sender = 1; sender <= 20; ++sender)
    core.edge_gaps_by_sender.emplace_back(sender, sender % 5 == 0 ? 100 : sender);
  const status_t st = toMessage(core);
  ASSERT_EQ(st.gap_senders, 16);
  EXPECT_EQ(st.gap_sender[0], 5);
  EXPECT_EQ(st.gap_count[0], 100);
  EXPECT_EQ(st.gap_sender[3], 20);
  EXPECT_EQ(st.gap_sender[4], 19);
  EXPECT_EQ(st.gap_count[4], 19);
  EXPECT_EQ(st.gap_sender[15], 6);  // 1, 2, 3 and 4 have the fewest: not listed
}

TEST(LcmServe, StatusListsTheGapsOfEachSender) {
  const PoseGraph2 graph = smallGraph();
  const std::vector<int> order = replayOrder(graph);
  lcm::LCM lcm("memq://");
  ServeOptions options;
  options.refine_on_exit = false;
  Service service(lcm, options);
  Collector collector(lcm, service.channels());
  service.start();
  // Sender 1 sends the stream with seq 4..6 missing; sender 2 repeats its first edge as seq 1
  // and 5 (2..4 missing; the smoother drops the repeated measurement, the intake counts seqs).
  for (size_t k = 0; k < 12; ++k) {
    if (k >= 3 && k < 6) continue;
    publishInOrder(lcm, service, graph, order, k);
  }
  for (std::int64_t seq : {1, 5}) {
    const auto bytes = edgeBytes(streamEdge(graph, order[0], seq, 2));
    lcm.publish(service.channels().edges, bytes.data(), static_cast<unsigned>(bytes.size()));
  }
  command_t c;
  c.command = command_t::STATUS;
  const auto cb = encodeMessage(c);
  lcm.publish(service.channels().command, cb.data(), static_cast<unsigned>(cb.size()));
  ASSERT_TRUE(collector.waitStatus([](const status_t& s) { return s.received == 11; }));
  const status_t s = collector.status();
  EXPECT_EQ(s.gaps, 6);
  ASSERT_EQ(s.gap_senders, 2);
  EXPECT_EQ(s.gap_sender[0], 1);  // 3 each: the lower sender first
  EXPECT_EQ(s.gap_count[0], 3);
  EXPECT_EQ(s.gap_sender[1], 2);
  EXPECT_EQ(s.gap_count[1], 3);
  service.stop();
}

TEST(LcmServe, CommandsRefinePublishAndSnapshot) {
  const PoseGraph2 graph = smallGraph();
  const std::vector<int> order = replayOrder(graph);
  lcm::LCM lcm("memq://");
  ServeOptions options;
  options.refine_on_exit = false;
  const std::string dir = tempJournal("snapshots");
  std::filesystem::create_directories(dir);
  options.snapshot_dir = dir;
  Service service(lcm, options);
  Collector collector(lcm, service.channels());
  service.start();
  for (size_t k = 0; k < order.size(); ++k) {
    publishInOrder(lcm, service, graph, order, k);
  }
  ASSERT_TRUE(collector.waitCovered(static_cast<std::int64_t>(order.size())));
  const std::string snapshot = dir + "/snapshot.g2o";
  for (std::int8_t kind : {command_t::REFINE, command_t::PUBLISH_FULL, command_t::SNAPSHOT}) {
    command_t c;
    c.command = kind;
    c.path = kind == command_t::SNAPSHOT ? "snapshot.g2o" : "";
    const auto b = encodeMessage(c);
    lcm.publish(service.channels().command, b.data(), static_cast<unsigned>(b.size()));
  }
  EXPECT_TRUE(collector.waitStatus([](const status_t& s) { return s.refinements == 1; }));
  // After REFINE and PUBLISH_FULL; the snapshot follows in the same command batch.
  for (int tries = 0;
       tries < 3000 && (collector.fullEstimates().size() < 2 || !std::filesystem::exists(snapshot));
       ++tries) {
    std::this_thread::sleep_for(std::chrono::milliseconds(10));
  }
  service.stop();
  EXPECT_GE(collector.fullEstimates().size(), 2u);
  const AnyPoseGraph back = readPoseGraphFile(snapshot);
  const auto& g = std::get<PoseGraph2>(back);
  EXPECT_EQ(g.numPoses(), graph.numPoses());
  EXPECT_EQ(g.numEdges(), graph.numEdges());
  const status_t st = service.status();
  EXPECT_LE(st.refine_F_after, st.refine_F_before);
  std::filesystem::remove_all(dir);
}

TEST(LcmServe, JournalRestartReproducesTheEstimateExactly) {
  const PoseGraph2 graph = smallGraph();
  const std::vector<int> order = replayOrder(graph);
  const size_t half = order.size() / 2;
  const std::string journal = tempJournal("journal.lcmlog");
  Estimate before;
  {
    lcm::LCM lcm("memq://");
    ServeOptions options;
    options.refine_on_exit = false;
    options.journal_path = journal;
    options.fsync_interval_ms = 20;
    Service service(lcm, options);
    Collector collector(lcm, service.channels());
    service.start();
    for (size_t k = 0; k < half; ++k) {
      publishInOrder(lcm, service, graph, order, k);
      if (k % 7 == 0) collector.waitCovered(static_cast<std::int64_t>(k) + 1);  // mixed grouping
    }
    ASSERT_TRUE(collector.waitCovered(static_cast<std::int64_t>(half)));
    service.stop();
    before = service.summary().final_estimate;
  }
  lcm::LCM lcm("memq://");
  ServeOptions options;
  options.journal_path = journal;
  Service service(lcm, options);
  Collector collector(lcm, service.channels());
  service.start();  // replays and publishes the replayed estimate before anything else
  // The first full estimate is published in start(), before the collector's thread runs it;
  // compare through a PUBLISH_FULL command instead.
  command_t c;
  c.command = command_t::PUBLISH_FULL;
  const auto cb = encodeMessage(c);
  lcm.publish(service.channels().command, cb.data(), static_cast<unsigned>(cb.size()));
  for (int tries = 0; tries < 200 && collector.fullEstimates().empty(); ++tries) {
    std::this_thread::sleep_for(std::chrono::milliseconds(10));
  }
  const std::vector<estimate_t> full = collector.fullEstimates();
  ASSERT_FALSE(full.empty());
  // Bit for bit: the same ids and the same numbers on the wire.
  EXPECT_EQ(full.back().ids, before.ids);
  EXPECT_EQ(full.back().translation, before.translation);
  EXPECT_EQ(full.back().rotation, before.rotation);
  EXPECT_EQ(full.back().last_seq, static_cast<std::int64_t>(half));
  for (size_t k = half; k < order.size(); ++k) {
    publishInOrder(lcm, service, graph, order, k);
  }
  ASSERT_TRUE(collector.waitCovered(static_cast<std::int64_t>(order.size())));
  service.stop();
  const ServeSummary& s = service.summary();
  EXPECT_EQ(s.journal_edges, static_cast<std::int64_t>(half));
  EXPECT_EQ(s.applied, static_cast<std::int64_t>(order.size()));
  EXPECT_EQ(s.intake.gaps, 0);
  EXPECT_EQ(s.final_estimate.num_poses, graph.numPoses());
  const OnlineSmoother2 replay = finalizedReplay(graph, order);
  EXPECT_NEAR(s.F_final, replay.smoother().objective(), 1e-9 * replay.smoother().objective());
  std::remove(journal.c_str());
}

TEST(EdgeIntake, PriorsHaveTheirOwnSeqsAndShareTheStreamsDim) {
  const PoseGraph2 graph = smallGraph();
  EdgeIntake intake;
  auto prior = [](std::int64_t seq, std::int64_t sender = 1) {
    StreamPositionPrior<SE2> p;
    p.sender = sender;
    p.seq = seq;
    p.id = 3;
    p.p = Eigen::Vector2d(1, 2);
    return encodeMessage(makePriorMessage(p));
  };
  auto admitPrior = [&](const std::vector<std::uint8_t>& b) {
    return intake.admitPrior(b.data(), static_cast<int>(b.size()));
  };
  const auto edge1 = edgeBytes(streamEdge(graph, 0, 1));
  EXPECT_EQ(intake.admit(edge1.data(), static_cast<int>(edge1.size())).verdict, Intake::kAccepted);
  // The same (sender, seq) as the edge: another stream, so not "seq reused".
  const IntakeResult p1 = admitPrior(prior(1));
  EXPECT_EQ(p1.verdict, Intake::kAccepted);
  EXPECT_TRUE(p1.is_prior);
  EXPECT_TRUE(std::holds_alternative<StreamPositionPrior<SE2>>(p1.prior));
  EXPECT_EQ(admitPrior(prior(1)).verdict, Intake::kDuplicate);
  EXPECT_EQ(admitPrior(prior(4)).skipped, 2);
  EXPECT_EQ(intake.priorCounts().gaps, 2);
  EXPECT_EQ(intake.counts().gaps, 0);
  StreamPosePrior<SE3> p3;
  p3.seq = 5;
  const IntakeResult wrong = admitPrior(encodeMessage(makePriorMessage(p3)));
  EXPECT_EQ(wrong.reason, "dim");
  EXPECT_NE(wrong.detail.find("3D prior on a 2D stream"), std::string::npos) << wrong.detail;
  const IntakeResult six = admitPrior(prior(6));
  intake.revoke(six, "journal");
  EXPECT_EQ(admitPrior(prior(6)).verdict, Intake::kAccepted);
  const IntakeCounts& c = intake.priorCounts();
  EXPECT_EQ(c.received, 6);
  EXPECT_EQ(c.accepted, 3);
  EXPECT_EQ(c.duplicates, 1);
  EXPECT_EQ(c.rejected, 2);
  EXPECT_EQ(c.rejected_by_reason.at("dim"), 1);
  EXPECT_EQ(c.rejected_by_reason.at("journal"), 1);
  EXPECT_EQ(intake.counts().received, 1);  // the edge counts are the edges'
  EXPECT_EQ(intake.counts().rejected, 0);
  // A prior first fixes the stream's dimension for the edges too.
  EdgeIntake fresh;
  EXPECT_EQ(fresh
                .admitPrior(encodeMessage(makePriorMessage(p3)).data(),
                            static_cast<int>(encodeMessage(makePriorMessage(p3)).size()))
                .verdict,
            Intake::kAccepted);
  EXPECT_EQ(fresh.dim(), 3);
  EXPECT_EQ(fresh.admit(edge1.data(), static_cast<int>(edge1.size())).reason, "dim");
}

TEST(StreamOrder, EachPriorFollowsTheEdgeThatIntroducesItsPose) {
  const PoseGraph2 graph = testing::manhattanGraphWithPriors(150, 3);
  const std::vector<cli::StreamStep> order = cli::streamOrder(graph);
  ASSERT_EQ(order.size(),
            graph.edges.size() + graph.pose_priors.size() + graph.position_priors.size());
  std::vector<bool> known(graph.ids.size(), false);
  int last_edge = -1, priors = 0;
  for (const cli::StreamStep& step : order) {
    if (step.kind == cli::StreamStep::Kind::kEdge) {
      const auto& e = graph.edges[step.index];
      known[e.i] = known[e.j] = true;
      last_edge = step.index;
      continue;
    }
    ++priors;
    const int pose = step.kind == cli::StreamStep::Kind::kPosePrior
                         ? graph.pose_priors[step.index].i
                         : graph.position_priors[step.index].i;
    ASSERT_GE(last_edge, 0);
    EXPECT_TRUE(known[pose]) << "a prior on pose " << pose << " before its pose";
    // The edge just before it (or before the priors just before it) touches the pose first.
    const auto& e = graph.edges[last_edge];
    EXPECT_TRUE(e.i == pose || e.j == pose) << "pose " << pose;
  }
  EXPECT_EQ(priors, graph.numPriors());
  // --count K then --skip K: every message once, each prior with its edge's part.
  cli::StreamSelection a, b;
  const auto first = cli::streamMessages(graph, 1, 0, 40, &a);
  const auto rest = cli::streamMessages(graph, 1, 40, -1, &b);
  EXPECT_EQ(a.edges + b.edges, graph.numEdges());
  EXPECT_EQ(a.priors + b.priors, graph.numPriors());
  EXPECT_GT(a.priors, 0);
  EXPECT_EQ(first.size() + rest.size(), order.size());
  EXPECT_EQ(b.first_seq, 41);
  // Prior seqs continue across the two parts.
  auto seqOf = [](const cli::StreamMessage<SE2>& m) {
    return std::visit([](const auto& p) { return p.seq; }, m.prior);
  };
  std::int64_t expected = 1;
  for (const auto* part : {&first, &rest}) {
    for (const auto& m : *part) {
      if (m.is_prior) {
        EXPECT_EQ(seqOf(m), expected++);
      }
    }
  }
}

// Publishes a message and a STATUS command, and waits for the status that counts `applied`
// edges and priors: one update per message, as the reference is fed.
void publishAndWait(lcm::LCM& lcm, const Service& service, Collector& collector,
                    const testing::StreamBytes& m, std::int64_t applied) {
  const std::string& ch = m.is_prior ? service.channels().priors : service.channels().edges;
  lcm.publish(ch, m.bytes.data(), static_cast<unsigned>(m.bytes.size()));
  command_t c;
  c.command = command_t::STATUS;
  const auto cb = encodeMessage(c);
  lcm.publish(service.channels().command, cb.data(), static_cast<unsigned>(cb.size()));
  ASSERT_TRUE(collector.waitStatus([&](const status_t& s) {
    return s.applied + s.priors_applied == applied;
  })) << "message "
      << applied;
}

TEST(LcmServe, EdgesAndPriorsInLockstepEqualTheSmootherFedDirectly) {
  SE2 world;
  const PoseGraph2 graph = testing::manhattanGraphWithPriors(150, 3, &world);
  cli::StreamSelection selection;
  const std::vector<testing::StreamBytes> messages = testing::streamBytes(graph, &selection);
  ASSERT_EQ(selection.priors, graph.numPriors());
  lcm::LCM lcm("memq://");
  ASSERT_TRUE(lcm.good());
  ServeOptions options;
  options.refine_on_exit = false;
  Service service(lcm, options);
  Collector collector(lcm, service.channels());
  service.start();
  OnlineSmoother2 reference;
  for (size_t k = 0; k < messages.size(); ++k) {
    publishAndWait(lcm, service, collector, messages[k], static_cast<std::int64_t>(k) + 1);
    ASSERT_TRUE(testing::feed(reference, messages[k])) << "message " << k;
    reference.update();
  }
  const status_t status = collector.status();
  service.stop();
  const ServeSummary& s = service.summary();
  EXPECT_EQ(s.applied, graph.numEdges());
  EXPECT_EQ(s.priors_applied, graph.numPriors());
  EXPECT_EQ(s.updates, static_cast<std::int64_t>(messages.size()));
  EXPECT_EQ(s.prior_intake.received, graph.numPriors());
  EXPECT_EQ(s.prior_intake.rejected + s.smoother_priors_rejected, 0);
  EXPECT_EQ(s.prior_intake.gaps, 0);
  EXPECT_EQ(status.priors_received, graph.numPriors());
  EXPECT_EQ(status.priors_accepted, graph.numPriors());
  EXPECT_EQ(status.priors_applied, graph.numPriors());
  EXPECT_EQ(status.queue_depth, 0);
  EXPECT_EQ(s.components, reference.stats().components);
  EXPECT_EQ(status.components, reference.stats().components);
  // Same inputs, same grouping: the very same estimate.
  expectSamePoses(s.final_estimate, reference.estimates(), 0.0);
  // The priors were applied: the estimate is in their frame, not the first pose's.
  const auto& ids = s.final_estimate.ids;
  const size_t first = static_cast<size_t>(std::find(ids.begin(), ids.end(), 0) - ids.begin());
  ASSERT_LT(first, ids.size());
  const Eigen::Vector2d x0(s.final_estimate.translation[first][0],
                           s.final_estimate.translation[first][1]);
  EXPECT_LT((x0 - world.translation()).norm(), 0.5) << x0.transpose();
  EXPECT_GT(world.translation().norm(), 5);
}

TEST(LcmServe, JournalRestartReplaysPriorsInTheirOrderAmongTheEdges) {
  const PoseGraph2 graph = testing::manhattanGraphWithPriors(150, 5);
  const std::vector<testing::StreamBytes> messages = testing::streamBytes(graph);
  const size_t half = messages.size() / 2;
  std::int64_t half_edges = 0, half_priors = 0;
  for (size_t k = 0; k < half; ++k) ++(messages[k].is_prior ? half_priors : half_edges);
  ASSERT_GT(half_priors, 3);
  const std::string journal = tempJournal("priors.lcmlog");
  Estimate before;
  {
    lcm::LCM lcm("memq://");
    ServeOptions options;
    options.refine_on_exit = false;
    options.journal_path = journal;
    Service service(lcm, options);
    Collector collector(lcm, service.channels());
    service.start();
    for (size_t k = 0; k < half; ++k) {
      if (k % 9 == 0) {  // mixed grouping: some updates of one message, some of several
        publishAndWait(lcm, service, collector, messages[k], static_cast<std::int64_t>(k) + 1);
      } else {
        const auto& m = messages[k];
        lcm.publish(m.is_prior ? service.channels().priors : service.channels().edges,
                    m.bytes.data(), static_cast<unsigned>(m.bytes.size()));
      }
    }
    publishAndWait(lcm, service, collector, messages[half - 1], static_cast<std::int64_t>(half));
    service.stop();
    EXPECT_EQ(service.summary().intake.duplicates + service.summary().prior_intake.duplicates, 1);
    before = service.summary().final_estimate;
  }
  // The journal holds the messages in the order sent (its edge and prior events, with marks).
  {
    const EventLogContents log = readEventLog(journal);
    std::vector<std::vector<std::uint8_t>> journaled;
    for (const LogEvent& e : log.events) {
      if (e.channel == Channels::withPrefix("").edges ||
          e.channel == Channels::withPrefix("").priors)
        journaled.push_back(e.data);
    }
    ASSERT_EQ(journaled.size(), half);
    for (size_t k = 0; k < half; ++k) EXPECT_EQ(journaled[k], messages[k].bytes) << k;
  }
  lcm::LCM lcm("memq://");
  ServeOptions options;
  options.journal_path = journal;
  Service service(lcm, options);
  Collector collector(lcm, service.channels());
  service.start();
  command_t c;
  c.command = command_t::PUBLISH_FULL;
  const auto cb = encodeMessage(c);
  lcm.publish(service.channels().command, cb.data(), static_cast<unsigned>(cb.size()));
  ASSERT_TRUE(collector.waitFull(1));
  const estimate_t after = collector.fullEstimates().back();
  // Bit for bit: the same ids and the same numbers on the wire.
  EXPECT_EQ(after.ids, before.ids);
  EXPECT_EQ(after.translation, before.translation);
  EXPECT_EQ(after.rotation, before.rotation);
  for (size_t k = half; k < messages.size(); ++k) {
    const auto& m = messages[k];
    lcm.publish(m.is_prior ? service.channels().priors : service.channels().edges, m.bytes.data(),
                static_cast<unsigned>(m.bytes.size()));
  }
  publishAndWait(lcm, service, collector, messages.back(),
                 static_cast<std::int64_t>(messages.size()));
  service.stop();
  const ServeSummary& s = service.summary();
  EXPECT_EQ(s.journal_edges, half_edges);
  EXPECT_EQ(s.journal_priors, half_priors);
  EXPECT_EQ(s.applied, graph.numEdges());
  EXPECT_EQ(s.priors_applied, graph.numPriors());
  EXPECT_EQ(s.intake.gaps + s.prior_intake.gaps, 0);
  // Refined on exit: F as the smoother fed directly and finalized.
  OnlineSmoother2 reference;
  for (const auto& m : messages) {
    ASSERT_TRUE(testing::feed(reference, m));
    reference.update();
  }
  reference.finalize();
  const double F = reference.smoother().objective();
  EXPECT_NEAR(s.F_final, F, 1e-9 * F);
  std::remove(journal.c_str());
}

TEST(LcmServe, HostilePriorsAreRefusedWithTheirReasonAndNothingElseIsLost) {
  const PoseGraph2 graph = testing::manhattanGraphWithPriors(150, 3);
  const std::vector<testing::StreamBytes> messages = testing::streamBytes(graph);
  lcm::LCM lcm("memq://");
  std::ostringstream log;
  ServeOptions options;  // refine on exit, as the reference finalizes
  options.log = &log;
  options.log_period = std::chrono::milliseconds(0);  // every line, for the assertions on them
  Service service(lcm, options);
  Collector collector(lcm, service.channels());
  service.start();
  const Channels& ch = service.channels();
  auto send = [&](const std::string& channel, const std::vector<std::uint8_t>& b) {
    lcm.publish(channel, b.data(), static_cast<unsigned>(b.size()));
  };
  StreamPosePrior<SE2> base;
  base.sender = 2;
  base.id = 7;
  base.z = SE2(1, 2, 0.3);
  std::int64_t seq = 0;
  auto hostile = [&](auto mutate) {
    prior_t m = makePriorMessage(base);
    m.seq = ++seq;
    mutate(m);
    return encodeMessage(m);
  };
  const double nan = std::numeric_limits<double>::quiet_NaN();
  std::map<std::string, int> expected;
  for (size_t k = 0; k < messages.size(); ++k) {
    send(messages[k].is_prior ? ch.priors : ch.edges, messages[k].bytes);
    switch (k % 10) {
      case 1:
        send(ch.priors, hostile([&](prior_t& m) { m.translation[0] = nan; }));
        ++expected["not finite"];
        break;
      case 2:
        send(ch.priors, hostile([](prior_t& m) {
               m.information_size = 5;
               m.information.resize(5);
             }));
        ++expected["dim"];
        break;
      case 3:
        send(ch.priors, hostile([](prior_t& m) { m.information[0] = -m.information[0]; }));
        ++expected["information"];
        break;
      case 4:
        send(ch.priors, hostile([](prior_t& m) { m.kind = 9; }));
        ++expected["kind"];
        break;
      case 5: {  // a 3D prior on this 2D stream
        StreamPositionPrior<SE3> p3;
        p3.sender = 2;
        p3.seq = ++seq;
        send(ch.priors, encodeMessage(makePriorMessage(p3)));
        ++expected["dim"];
        break;
      }
      case 6: {
        const auto b = hostile([](prior_t&) {});
        send(ch.priors, std::vector<std::uint8_t>(b.begin(), b.begin() + 100));
        ++expected["truncated"];
        break;
      }
      case 7:  // an edge on the priors channel
        send(ch.priors, edgeBytes(streamEdge(graph, 0, 1, 3)));
        ++expected["type hash"];
        break;
      case 8:
        send(ch.priors, hostile([](prior_t& m) { m.translation[1] = -1e200; }));
        ++expected["magnitude"];
        break;
      default:
        break;
    }
  }
  publishAndWait(lcm, service, collector, messages.back(),
                 static_cast<std::int64_t>(messages.size()));  // a duplicate, then the count
  service.stop();
  const ServeSummary& s = service.summary();
  EXPECT_EQ(s.applied, graph.numEdges());
  EXPECT_EQ(s.priors_applied, graph.numPriors());
  EXPECT_EQ(s.intake.rejected, 0);
  int total = 0;
  for (const auto& [reason, n] : expected) {
    const auto& by = s.prior_intake.rejected_by_reason;
    EXPECT_EQ(by.count(reason) ? by.at(reason) : 0, n) << reason;
    total += n;
  }
  EXPECT_EQ(s.prior_intake.rejected, total);
  EXPECT_EQ(s.prior_intake.accepted, graph.numPriors());
  const status_t st = service.status();
  EXPECT_EQ(st.priors_rejected, total);
  const auto at = std::find(st.reason.begin(), st.reason.end(), "prior kind");
  ASSERT_NE(at, st.reason.end());
  EXPECT_EQ(st.reason_count[static_cast<size_t>(at - st.reason.begin())], expected["kind"]);
  EXPECT_NE(log.str().find("rejected prior (sender 2 seq"), std::string::npos) << log.str();
  EXPECT_NE(log.str().find("kind 9 is not POSE (1) or POSITION (2)"), std::string::npos);
  // Nothing accepted was lost: the estimate is that of the good messages alone (fed directly
  // with the grouping of a burst, so compared after finalizing both).
  OnlineSmoother2 reference;
  for (const auto& m : messages) {
    ASSERT_TRUE(testing::feed(reference, m));
    reference.update();
  }
  reference.finalize();
  const double F = reference.smoother().objective();
  EXPECT_NEAR(s.F_final, F, 1e-9 * F);
  EXPECT_EQ(s.final_estimate.num_poses, graph.numPoses());
}

// A journal damaged in the middle (one edge event's header overwritten) loses that edge only:
// the restart replays every journaled edge after it.
TEST(LcmServe, JournalDamagedInTheMiddleLosesOnlyTheDamagedEdge) {
  const PoseGraph2 graph = smallGraph();
  const std::vector<int> order = replayOrder(graph);
  const size_t sent = order.size() / 2;
  const std::string journal = tempJournal("damaged.lcmlog");
  {
    lcm::LCM lcm("memq://");
    ServeOptions options;
    options.refine_on_exit = false;
    options.journal_path = journal;
    Service service(lcm, options);
    Collector collector(lcm, service.channels());
    service.start();
    for (size_t k = 0; k < sent; ++k) {
      publishInOrder(lcm, service, graph, order, k);
    }
    ASSERT_TRUE(collector.waitCovered(static_cast<std::int64_t>(sent)));
    service.stop();
    EXPECT_EQ(service.summary().applied, static_cast<std::int64_t>(sent));
  }
  // Events are written back to back: find the offset of an edge event in the middle.
  const EventLogContents log = readEventLog(journal);
  std::int64_t offset = 0, target = -1;
  int edges_seen = 0;
  for (const LogEvent& e : log.events) {
    const bool is_edge = e.channel == Channels::withPrefix("").edges;
    if (is_edge && ++edges_seen == static_cast<int>(sent / 2)) target = offset;
    offset += 4 + 8 + 8 + 4 + 4 + static_cast<std::int64_t>(e.channel.size() + e.data.size());
  }
  ASSERT_GE(target, 0);
  ASSERT_EQ(offset, log.file_bytes);
  {
    std::fstream f(journal, std::ios::binary | std::ios::in | std::ios::out);
    f.seekp(target + 20);  // the channel length
    const char garbage[4] = {'\x7f', '\x7f', '\x7f', '\x7f'};
    f.write(garbage, sizeof garbage);
  }
  lcm::LCM lcm("memq://");
  ServeOptions options;
  options.refine_on_exit = false;
  options.journal_path = journal;
  Service service(lcm, options);
  service.start();
  service.stop();
  EXPECT_EQ(service.summary().journal_edges, static_cast<std::int64_t>(sent) - 1);
  std::remove(journal.c_str());
}

}  // namespace
}  // namespace arbor::serve
