// Edge commands (edge_command_t on ARBOR_EDGE_COMMANDS) in `arbor serve`, in process over
// memq://: their own per-sender seqs in the intake; a stream of edges, a planted false closure
// and commands in lockstep gives bit for bit the estimate of an OnlineSmoother fed the same
// (disableEdge where the command came), with the counts and the last result in status_t;
// hostile commands are refused with their reason and nothing accepted is lost; a journal
// restart replays the commands in their order among the edges.
#include <algorithm>
#include <chrono>
#include <cstdio>
#include <limits>
#include <map>
#include <sstream>
#include <string>
#include <vector>

#include <gtest/gtest.h>

#include "arbor_slam/bayestree/online_smoother.h"
#include "arbor_slam/io/lcm_journal.h"
#include "arbor_slam/io/lcm_messages.h"
#include "arbor_slam/tests/lcm_test_support.h"
#include "arbor_slam/tools/serve/serve_service.h"

namespace arbor::serve {
namespace {

using testing::Collector;

StreamEdgeCommand command(std::int64_t seq, StreamEdgeCommand::Kind kind, Key from, Key to,
                          std::int64_t sender = 3) {
  StreamEdgeCommand c;
  c.sender = sender;
  c.seq = seq;
  c.kind = kind;
  c.from = from;
  c.to = to;
  return c;
}

std::vector<std::uint8_t> commandBytes(const StreamEdgeCommand& c) {
  return encodeMessage(makeEdgeCommandMessage(c));
}

TEST(EdgeIntake, EdgeCommandsHaveTheirOwnSeqsAndReasons) {
  EdgeIntake intake(2);
  auto admit = [&](const std::vector<std::uint8_t>& b) {
    return intake.admitCommand(b.data(), static_cast<int>(b.size()));
  };
  using Kind = StreamEdgeCommand::Kind;
  const IntakeResult one = admit(commandBytes(command(1, Kind::kDisable, 4, 9)));
  ASSERT_EQ(one.verdict, Intake::kAccepted) << one.detail;
  EXPECT_TRUE(one.is_command);
  EXPECT_EQ(one.command.from, 4);
  EXPECT_EQ(one.command.to, 9);
  EXPECT_EQ(admit(commandBytes(command(1, Kind::kDisable, 4, 9))).verdict, Intake::kDuplicate);
  EXPECT_EQ(admit(commandBytes(command(1, Kind::kEnable, 4, 9))).reason, "seq reused");
  EXPECT_EQ(admit(commandBytes(command(4, Kind::kEnable, 4, 9))).skipped, 2);
  // An edge of the same sender and seq is another stream: no conflict.
  StreamEdge<SE2> e;
  e.sender = 3;
  e.seq = 1;
  e.from = 4;
  e.to = 9;
  const auto edge = encodeMessage(makeEdgeMessage(e));
  EXPECT_EQ(intake.admit(edge.data(), static_cast<int>(edge.size())).verdict, Intake::kAccepted);
  // Hostile: an edge's bytes on the commands channel, a bad kind, a negative id, a self-loop.
  EXPECT_EQ(admit(edge).reason, "type hash");
  edge_command_t bad = makeEdgeCommandMessage(command(5, Kind::kDisable, 4, 9));
  bad.command = 9;
  const IntakeResult kind = admit(encodeMessage(bad));
  EXPECT_EQ(kind.reason, "kind");
  EXPECT_NE(kind.detail.find("command 9"), std::string::npos) << kind.detail;
  EXPECT_EQ(admit(commandBytes(command(5, Kind::kDisable, -2, 9))).reason, "id");
  EXPECT_EQ(admit(commandBytes(command(5, Kind::kDisable, 9, 9))).reason, "self-loop");
  const IntakeCounts& c = intake.commandCounts();
  EXPECT_EQ(c.received, 8);
  EXPECT_EQ(c.accepted, 2);
  EXPECT_EQ(c.duplicates, 1);
  EXPECT_EQ(c.rejected, 5);
  EXPECT_EQ(c.gaps, 2);
  EXPECT_EQ(intake.counts().accepted, 1);  // the edge
}

// One message of the stream: an edge (graph edge or the planted closure) or an edge command.
struct Message {
  bool is_command = false;
  std::vector<std::uint8_t> bytes;
};

/// The graph's edges in replay order (sender 1), a false closure 10 → 100 (sender 2) right
/// after pose 100 arrives, a disable of it 15 edges later, then three commands the smoother
/// refuses (already disabled, an unknown pose, an enable of a pair never disabled), all sender 3.
std::vector<Message> streamWithCommands(const PoseGraph2& graph, Key bad_from, Key bad_to) {
  std::vector<Message> out;
  using Kind = StreamEdgeCommand::Kind;
  int after_bad = -1;
  std::int64_t seq = 0;
  for (const auto& m : testing::streamBytes(graph)) {
    out.push_back({false, m.bytes});
    const auto e = std::get<StreamEdge<SE2>>(
        decodeEdge(m.bytes.data(), static_cast<int>(m.bytes.size())).edge);
    EXPECT_FALSE(std::min(e.from, e.to) == std::min(bad_from, bad_to) &&
                 std::max(e.from, e.to) == std::max(bad_from, bad_to))
        << "the graph has an edge " << bad_from << " - " << bad_to << " already";
    if (after_bad < 0 && std::max(e.from, e.to) == bad_to) {
      StreamEdge<SE2> bad;
      bad.sender = 2;
      bad.seq = 1;
      bad.from = bad_from;
      bad.to = bad_to;
      bad.z = SE2(1.0, 0.0, 0.0);
      bad.omega = e.omega;
      out.push_back({false, testing::edgeBytes(bad)});
      after_bad = 0;
    } else if (after_bad >= 0 && ++after_bad == 15) {
      out.push_back({true, commandBytes(command(++seq, Kind::kDisable, bad_to, bad_from))});
    } else if (after_bad == 30) {
      out.push_back({true, commandBytes(command(++seq, Kind::kDisable, bad_from, bad_to))});
      out.push_back({true, commandBytes(command(++seq, Kind::kDisable, bad_from, 99999))});
      out.push_back({true, commandBytes(command(++seq, Kind::kEnable, e.from, e.to))});
    }
  }
  return out;
}

void publish(lcm::LCM& lcm, const Service& service, const Message& m) {
  const std::string& ch =
      m.is_command ? service.channels().edge_commands : service.channels().edges;
  lcm.publish(ch, m.bytes.data(), static_cast<unsigned>(m.bytes.size()));
}

/// Publishes a message and a STATUS command and waits for the status counting `applied` edges
/// and commands: one update per message, as the reference is fed.
void publishAndWait(lcm::LCM& lcm, const Service& service, Collector& collector, const Message& m,
                    std::int64_t applied) {
  publish(lcm, service, m);
  command_t c;
  c.command = command_t::STATUS;
  const auto cb = encodeMessage(c);
  lcm.publish(service.channels().command, cb.data(), static_cast<unsigned>(cb.size()));
  ASSERT_TRUE(collector.waitStatus([&](const status_t& s) {
    return s.applied + s.commands_applied == applied;
  })) << "message "
      << applied;
}

/// Feeds one message to `smoother` as the service does; the command's result when a command.
EdgeSwitchResult feed(OnlineSmoother2& smoother, const Message& m) {
  const int size = static_cast<int>(m.bytes.size());
  if (!m.is_command) {
    const EdgeDecoding d = decodeEdge(m.bytes.data(), size);
    EXPECT_TRUE(d.ok()) << d.detail;
    const auto& e = std::get<StreamEdge<SE2>>(d.edge);
    EXPECT_EQ(smoother.addEdge(e.from, e.to, e.z, e.omega).status, EdgeStatus::kAccepted);
    return {};
  }
  const EdgeCommandDecoding d = decodeEdgeCommand(m.bytes.data(), size);
  EXPECT_TRUE(d.ok()) << d.detail;
  return d.command.kind == StreamEdgeCommand::Kind::kDisable
             ? smoother.disableEdge(d.command.from, d.command.to)
             : smoother.enableEdge(d.command.from, d.command.to);
}

template <class Message>  // estimate_t or Estimate
void expectSameEstimate(const Message& m, const OnlineSmoother2& reference) {
  const auto expected = reference.estimates();
  ASSERT_EQ(m.num_poses, static_cast<int>(expected.size()));
  for (int k = 0; k < m.num_poses; ++k) {
    double t[3], r[4];
    poseToFields(expected.at(m.ids[k]), t, r);
    EXPECT_EQ(m.translation[k][0], t[0]) << "pose " << m.ids[k];
    EXPECT_EQ(m.translation[k][1], t[1]) << "pose " << m.ids[k];
    EXPECT_EQ(m.rotation[k][0], r[0]) << "pose " << m.ids[k];
  }
}

TEST(LcmServe, EdgeCommandsInLockstepEqualTheSmootherFedDirectly) {
  const PoseGraph2 graph = testing::manhattanGraph(150, 4, -1, 3);
  const std::vector<Message> messages = streamWithCommands(graph, 10, 100);
  lcm::LCM lcm("memq://");
  ASSERT_TRUE(lcm.good());
  std::ostringstream log;
  ServeOptions options;
  options.refine_on_exit = false;
  options.log = &log;
  Service service(lcm, options);
  Collector collector(lcm, service.channels());
  service.start();
  OnlineSmoother2 reference;
  std::vector<EdgeSwitchStatus> results;
  for (size_t k = 0; k < messages.size(); ++k) {
    publishAndWait(lcm, service, collector, messages[k], static_cast<std::int64_t>(k) + 1);
    const EdgeSwitchResult r = feed(reference, messages[k]);
    if (messages[k].is_command) results.push_back(r.status);
    reference.update();
  }
  const status_t status = collector.status();
  service.stop();
  ASSERT_EQ(results.size(), 4u);
  EXPECT_EQ(results[0], EdgeSwitchStatus::kApplied);
  EXPECT_EQ(results[1], EdgeSwitchStatus::kAlreadyDisabled);
  EXPECT_EQ(results[2], EdgeSwitchStatus::kUnknownPose);
  EXPECT_EQ(results[3], EdgeSwitchStatus::kAlreadyEnabled);
  const ServeSummary& s = service.summary();
  EXPECT_EQ(s.applied, graph.numEdges() + 1);
  EXPECT_EQ(s.command_intake.received, 4);
  EXPECT_EQ(s.command_intake.accepted, 4);
  EXPECT_EQ(s.commands_applied, 4);
  EXPECT_EQ(s.commands_refused, 3);
  EXPECT_EQ(s.commands_refused_by_reason.at("already disabled"), 1);
  EXPECT_EQ(s.commands_refused_by_reason.at("unknown pose"), 1);
  EXPECT_EQ(s.commands_refused_by_reason.at("already enabled"), 1);
  EXPECT_EQ(s.edges_disabled, 1);
  EXPECT_EQ(s.pairs_disabled, 1);
  EXPECT_EQ(status.commands_received, 4);
  EXPECT_EQ(status.commands_applied, 4);
  EXPECT_EQ(status.commands_refused, 3);
  EXPECT_EQ(status.edges_disabled, 1);
  EXPECT_EQ(status.queue_depth, 0);
  EXPECT_EQ(status.last_command_sender, 3);
  EXPECT_EQ(status.last_command_seq, 4);
  EXPECT_EQ(status.last_command_result.rfind("refused: enable edge", 0), 0u)
      << status.last_command_result;
  EXPECT_NE(log.str().find("99999"), std::string::npos) << log.str();
  // Same inputs, same grouping: the very same estimate, and F without the disabled closure.
  expectSameEstimate(s.final_estimate, reference);
  EXPECT_EQ(s.final_estimate.F, reference.objective());
  EXPECT_LT(reference.objective(), reference.smoother().objective());
}

TEST(LcmServe, HostileEdgeCommandsAreRefusedWithTheirReasonAndNothingElseIsLost) {
  const PoseGraph2 graph = testing::manhattanGraph(60, 4, -1, 5);
  const auto edges = testing::streamBytes(graph);
  lcm::LCM lcm("memq://");
  std::ostringstream log;
  ServeOptions options;
  options.refine_on_exit = false;
  options.log = &log;
  Service service(lcm, options);
  Collector collector(lcm, service.channels());
  service.start();
  using Kind = StreamEdgeCommand::Kind;
  // Before any pose: a well-formed command names no known pose and is refused by the smoother.
  publish(lcm, service, {true, commandBytes(command(1, Kind::kDisable, 0, 1))});
  for (const auto& m : edges) publish(lcm, service, {false, m.bytes});
  std::vector<std::vector<std::uint8_t>> hostile;
  edge_command_t m = makeEdgeCommandMessage(command(2, Kind::kDisable, 0, 1));
  m.command = 0;
  hostile.push_back(encodeMessage(m));  // kind
  m.command = edge_command_t::ENABLE_EDGE;
  m.from_id = std::numeric_limits<std::int64_t>::min();
  hostile.push_back(encodeMessage(m));  // id
  m.from_id = 0;
  m.seq = -1;
  hostile.push_back(encodeMessage(m));  // seq
  auto truncated = commandBytes(command(3, Kind::kDisable, 0, 1));
  truncated.resize(truncated.size() - 3);
  hostile.push_back(truncated);
  hostile.push_back(edges.front().bytes);  // an edge on the commands channel: type hash
  hostile.push_back(std::vector<std::uint8_t>(5, 0xff));  // garbage
  for (const auto& b : hostile) publish(lcm, service, {true, b});
  // Well-formed but beyond the graph: refused by the smoother, counted, nothing changes.
  publish(lcm, service,
          {true, commandBytes(command(4, Kind::kDisable, std::numeric_limits<Key>::max(), 0))});
  ASSERT_TRUE(collector.waitStatus([&](const status_t& s) {
    return s.applied == graph.numEdges() && s.commands_applied == 2 && s.commands_rejected == 6;
  })) << log.str();
  service.stop();
  const ServeSummary& s = service.summary();
  const auto& reasons = s.command_intake.rejected_by_reason;
  EXPECT_EQ(reasons.at("kind"), 1);
  EXPECT_EQ(reasons.at("id"), 1);
  EXPECT_EQ(reasons.at("seq"), 1);
  EXPECT_EQ(reasons.at("type hash"), 1);
  EXPECT_EQ(reasons.at("truncated"), 2);
  EXPECT_EQ(s.commands_refused_by_reason.at("unknown pose"), 2);
  EXPECT_EQ(s.edges_disabled, 0);
  EXPECT_EQ(s.applied, graph.numEdges());
  EXPECT_NE(log.str().find("command 0 is not DISABLE_EDGE"), std::string::npos) << log.str();
  EXPECT_NE(log.str().find("from_id -9223372036854775808 is negative"), std::string::npos);
  // The edges gave the estimate of the smoother fed them alone.
  OnlineSmoother2 reference;
  for (const auto& e : edges) ASSERT_TRUE(testing::feed(reference, e));
  EXPECT_EQ(s.final_estimate.num_poses, static_cast<int>(reference.estimates().size()));
}

// Issue 56: lines a sender can provoke go through the log limiter, the smoother's refusal of an
// edge command and an unknown command code as well: thousands of each give one line per reason
// in the period (the rest counted, never written).
TEST(LcmServe, AFloodOfRefusedCommandsWritesOneLogLinePerReasonPerPeriod) {
  lcm::LCM lcm("memq://");
  std::ostringstream log;
  ServeOptions options;
  options.refine_on_exit = false;
  options.log = &log;
  options.log_period = std::chrono::seconds(60);  // the whole test is one period
  Service service(lcm, options);
  Collector collector(lcm, service.channels());
  service.start();
  using Kind = StreamEdgeCommand::Kind;
  const int n = 3000;
  command_t unknown;
  unknown.command = 99;
  const std::vector<std::uint8_t> unknown_bytes = encodeMessage(unknown);
  for (int k = 0; k < n; ++k) {
    lcm.publish(service.channels().command, unknown_bytes.data(),
                static_cast<unsigned>(unknown_bytes.size()));
    // Before any pose: well-formed, refused by the smoother (unknown pose).
    publish(lcm, service, {true, commandBytes(command(k + 1, Kind::kDisable, 0, 1))});
  }
  ASSERT_TRUE(collector.waitStatus([&](const status_t& s) { return s.commands_applied == n; }))
      << log.str().substr(0, 2000);
  service.stop();
  EXPECT_EQ(service.summary().commands_refused_by_reason.at("unknown pose"), n);
  const std::string text = log.str();
  auto lines = [&](const std::string& what) {
    int count = 0;
    for (size_t at = text.find(what); at != std::string::npos; at = text.find(what, at + 1))
      ++count;
    return count;
  };
  EXPECT_EQ(lines("edge command (sender"), 1) << text.substr(0, 2000);
  EXPECT_EQ(lines("unknown command 99"), 1) << text.substr(0, 2000);
  EXPECT_LT(std::count(text.begin(), text.end(), '\n'), 40) << text.substr(0, 2000);
}

TEST(LcmServe, JournalRestartReplaysEdgeCommandsInTheirOrder) {
  const PoseGraph2 graph = testing::manhattanGraph(150, 4, -1, 3);
  const std::vector<Message> messages = streamWithCommands(graph, 10, 100);
  size_t first_command = 0;
  while (!messages[first_command].is_command) ++first_command;
  const size_t half = first_command + 10;  // the disable and some edges after it
  const std::string journal = testing::tempPath("arbor_lcm_commands", "journal.lcmlog");
  Estimate before;
  {
    lcm::LCM lcm("memq://");
    ServeOptions options;
    options.refine_on_exit = false;
    options.journal_path = journal;
    Service service(lcm, options);
    Collector collector(lcm, service.channels());
    service.start();
    for (size_t k = 0; k + 1 < half; ++k) publish(lcm, service, messages[k]);
    publishAndWait(lcm, service, collector, messages[half - 1], static_cast<std::int64_t>(half));
    service.stop();
    EXPECT_EQ(service.summary().edges_disabled, 1);
    before = service.summary().final_estimate;
  }
  {  // The journal holds the messages in the order sent, the command among the edges.
    const EventLogContents log = readEventLog(journal);
    std::vector<Message> journaled;
    for (const LogEvent& e : log.events) {
      if (e.channel == Channels::withPrefix("").edges) journaled.push_back({false, e.data});
      if (e.channel == Channels::withPrefix("").edge_commands) journaled.push_back({true, e.data});
    }
    ASSERT_EQ(journaled.size(), half);
    for (size_t k = 0; k < half; ++k) {
      EXPECT_EQ(journaled[k].is_command, messages[k].is_command) << k;
      EXPECT_EQ(journaled[k].bytes, messages[k].bytes) << k;
    }
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
  EXPECT_EQ(after.ids, before.ids);
  EXPECT_EQ(after.translation, before.translation);
  EXPECT_EQ(after.rotation, before.rotation);
  for (size_t k = half; k + 1 < messages.size(); ++k) publish(lcm, service, messages[k]);
  publishAndWait(lcm, service, collector, messages.back(),
                 static_cast<std::int64_t>(messages.size()));
  service.stop();
  const ServeSummary& s = service.summary();
  EXPECT_EQ(s.journal_commands, 1);
  EXPECT_EQ(s.commands_applied, 4);
  EXPECT_EQ(s.edges_disabled, 1);
  EXPECT_EQ(s.command_intake.gaps, 0);
  // Refined on exit: F as the smoother fed directly and finalized.
  OnlineSmoother2 reference;
  for (const auto& m : messages) {
    feed(reference, m);
    reference.update();
  }
  reference.finalize();
  const double F = reference.objective();
  EXPECT_NEAR(s.F_final, F, 1e-9 * F);
  std::remove(journal.c_str());
}

}  // namespace
}  // namespace arbor::serve
