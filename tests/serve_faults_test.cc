// `arbor serve` under faults it does not control, in-process over memq://: a full journal (a
// size limit, and a real full disk on a small tmpfs when this process may mount one) refuses
// edges without breaking write-ahead or the journal's exact replay; snapshots go only where the
// operator allowed; a flood of senders, oversize messages and commands is bounded and counted;
// log lines a sender can provoke are rate limited. Every wait is on a condition, with a
// generous timeout only as a failure guard.
#include <fcntl.h>
#include <sched.h>
#include <sys/mount.h>
#include <unistd.h>

#include <cerrno>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <set>
#include <sstream>
#include <string>
#include <vector>

#include <gtest/gtest.h>
#include <lcm/lcm-cpp.hpp>

#include "arbor_slam/io/lcm_journal.h"
#include "arbor_slam/io/lcm_messages.h"
#include "arbor_slam/io/pose_graph_file.h"
#include "arbor_slam/tests/lcm_test_support.h"
#include "arbor_slam/tools/serve/link_watch.h"
#include "arbor_slam/tools/serve/log_limiter.h"
#include "arbor_slam/tools/serve/serve_service.h"
#include "arbor_slam/tools/serve/snapshot_dir.h"

namespace arbor::serve {
namespace {

namespace fs = std::filesystem;
using testing::Collector;
using testing::edgeBytes;
using testing::replayOrder;
using testing::streamEdge;

constexpr double kGuard = 60;  // seconds: a failure guard, never a pacing

PoseGraph2 smallGraph() { return testing::manhattanGraph(150, 4, -1, 3); }

std::string tempDir(const std::string& name) {
  const std::string dir = testing::tempPath("arbor_serve_faults", name);
  fs::remove_all(dir);
  fs::create_directories(dir);
  return dir;
}

std::string readText(const std::string& path) {
  std::ifstream in(path);
  std::stringstream s;
  s << in.rdbuf();
  return s.str();
}

void publish(lcm::LCM& lcm, const std::string& channel, const std::vector<std::uint8_t>& bytes) {
  lcm.publish(channel, bytes.data(), static_cast<unsigned>(bytes.size()));
}

void sendCommand(lcm::LCM& lcm, const Service& service, std::int8_t kind,
                 const std::string& path = "") {
  command_t c;
  c.utime = nowMicros();
  c.command = kind;
  c.path = path;
  publish(lcm, service.channels().command, encodeMessage(c));
}

std::int64_t reasonCount(const status_t& s, const std::string& reason) {
  for (int k = 0; k < s.num_reasons; ++k)
    if (s.reason[k] == reason) return s.reason_count[k];
  return 0;
}

TEST(LogLimiter, OneLinePerKeyPerPeriodThenTheCountHeldBack) {
  LogLimiter limiter(std::chrono::seconds(1));
  const auto t0 = LogLimiter::Clock::time_point() + std::chrono::hours(1);
  std::int64_t held = -1;
  EXPECT_TRUE(limiter.allow("a", &held, t0));
  EXPECT_EQ(held, 0);
  for (int k = 0; k < 5; ++k)
    EXPECT_FALSE(limiter.allow("a", &held, t0 + std::chrono::milliseconds(10 * k)));
  EXPECT_TRUE(limiter.allow("b", &held, t0));  // keys are apart
  EXPECT_TRUE(limiter.allow("a", &held, t0 + std::chrono::seconds(1)));
  EXPECT_EQ(held, 5);
  EXPECT_EQ(LogLimiter::withSuppressed("x", 5), "x (5 more like it not logged)");
  EXPECT_EQ(LogLimiter::withSuppressed("x", 0), "x");
}

TEST(SnapshotDir, RefusesEveryNameThatIsNotAPlainFileName) {
  const std::vector<std::string> bad_names = {"",
                                              ".",
                                              "..",
                                              "../x",
                                              "/etc/x",
                                              "a/b",
                                              ".hidden",
                                              "x\ny",
                                              std::string("a\0b", 3),
                                              std::string(256, 'a'),
                                              "x y",
                                              "*",
                                              "-rf",
                                              "--help",
                                              "+x"};
  for (const std::string& bad : bad_names) {
    EXPECT_NE(SnapshotDir::checkName(bad), "") << SnapshotDir::printable(bad);
  }
  for (const std::string& good :
       std::vector<std::string>{"a", "snapshot.g2o", "run-2_final+1.g2o", "x..y", "a-"}) {
    EXPECT_EQ(SnapshotDir::checkName(good), "") << good;
  }
}

TEST(SnapshotDir, WritesNewNamesAndItsOwnFilesNeverAForeignOneOrThroughASymlink) {
  const std::string dir = tempDir("snapdir"), outside = tempDir("snapdir_outside");
  const auto writer = [](const std::string& text) {
    return [text](const std::string& path) { std::ofstream(path) << text; };
  };
  EXPECT_NE(SnapshotDir().write("a.g2o", writer("x")), "");  // unset: refused
  SnapshotDir snapshots(dir);
  std::ofstream(dir + "/foreign.g2o") << "foreign";
  fs::create_symlink(outside + "/target.g2o", dir + "/link.g2o");
  EXPECT_NE(snapshots.write("foreign.g2o", writer("ours")), "");
  EXPECT_EQ(readText(dir + "/foreign.g2o"), "foreign");
  EXPECT_NE(snapshots.write("link.g2o", writer("ours")), "");
  EXPECT_FALSE(fs::exists(outside + "/target.g2o"));
  EXPECT_NE(snapshots.write("../escape.g2o", writer("ours")), "");
  EXPECT_FALSE(fs::exists(fs::path(dir).parent_path() / "escape.g2o"));
  EXPECT_EQ(snapshots.write("ok.g2o", writer("one")), "");
  EXPECT_EQ(readText(dir + "/ok.g2o"), "one");
  EXPECT_EQ(snapshots.write("ok.g2o", writer("two")), "");  // its own file: replaced
  EXPECT_EQ(readText(dir + "/ok.g2o"), "two");
  // Replaced behind its back: no longer its file.
  fs::remove(dir + "/ok.g2o");
  std::ofstream(dir + "/ok.g2o") << "someone else";
  EXPECT_NE(snapshots.write("ok.g2o", writer("three")), "");
  EXPECT_EQ(readText(dir + "/ok.g2o"), "someone else");
  // A refused write leaves nothing behind (no temporaries).
  std::set<std::string> names;
  for (const auto& e : fs::directory_iterator(dir)) names.insert(e.path().filename().string());
  EXPECT_EQ(names, (std::set<std::string>{"foreign.g2o", "link.g2o", "ok.g2o"}));
  // At most kMaxNames names ("ok.g2o" is one): a flood of names is bounded.
  for (size_t k = 1; k < SnapshotDir::kMaxNames; ++k) {
    EXPECT_EQ(snapshots.write("n" + std::to_string(k), writer("x")), "") << k;
  }
  EXPECT_NE(snapshots.write("one-more", writer("x")), "");
  EXPECT_FALSE(fs::exists(dir + "/one-more"));
  fs::remove_all(dir);
  fs::remove_all(outside);
}

// Streams the first `count` edges of `graph` in replay order (sender 1, seq 1..count).
void streamEdges(lcm::LCM& lcm, const Service& service, const PoseGraph2& graph, size_t count) {
  const std::vector<int> order = replayOrder(graph);
  for (size_t k = 0; k < count && k < order.size(); ++k) {
    publish(lcm, service.channels().edges,
            edgeBytes(graph, order[k], static_cast<std::int64_t>(k) + 1));
  }
}

TEST(ServeFaults, SnapshotFromTheBusOnlyInsideTheSnapshotDir) {
  const PoseGraph2 graph = smallGraph();
  const std::string dir = tempDir("bus_snapshots"), outside = tempDir("bus_outside");
  std::ofstream(dir + "/foreign.g2o") << "foreign";
  fs::create_symlink(outside + "/target.g2o", dir + "/link.g2o");
  {
    // No --snapshot-dir: refused, whatever the path.
    lcm::LCM lcm("memq://");
    Service service(lcm, ServeOptions());
    Collector collector(lcm, service.channels());
    service.start();
    streamEdges(lcm, service, graph, 10);
    ASSERT_TRUE(collector.waitCovered(10, kGuard));
    sendCommand(lcm, service, command_t::SNAPSHOT, outside + "/abs.g2o");
    sendCommand(lcm, service, command_t::SNAPSHOT, "plain.g2o");
    sendCommand(lcm, service, command_t::STATUS);
    ASSERT_TRUE(
        collector.waitStatus([](const status_t& s) { return s.control_refused == 2; }, kGuard));
    service.stop();
    EXPECT_EQ(reasonCount(service.status(), "control snapshot no dir"), 2);
    EXPECT_FALSE(fs::exists(outside + "/abs.g2o"));
  }
  lcm::LCM lcm("memq://");
  ServeOptions options;
  options.snapshot_dir = dir;
  Service service(lcm, options);
  Collector collector(lcm, service.channels());
  service.start();
  streamEdges(lcm, service, graph, 10);
  ASSERT_TRUE(collector.waitCovered(10, kGuard));
  const std::vector<std::string> hostile = {"../x.g2o",  outside + "/x.g2o", "",        ".hidden",
                                            "sub/x.g2o", "foreign.g2o",      "link.g2o"};
  for (const auto& path : hostile) sendCommand(lcm, service, command_t::SNAPSHOT, path);
  sendCommand(lcm, service, command_t::SNAPSHOT, "ok.g2o");
  sendCommand(lcm, service, command_t::SNAPSHOT, "ok.g2o");  // its own file: written again
  sendCommand(lcm, service, command_t::STATUS);
  const auto refused = static_cast<std::int64_t>(hostile.size());
  ASSERT_TRUE(collector.waitStatus([&](const status_t& s) { return s.control_refused == refused; },
                                   kGuard));
  service.stop();
  const status_t s = service.status();
  EXPECT_EQ(reasonCount(s, "control snapshot name"), 5);     // "..", absolute, "", hidden, "/"
  EXPECT_EQ(reasonCount(s, "control snapshot refused"), 2);  // foreign file, symlink
  EXPECT_EQ(readText(dir + "/foreign.g2o"), "foreign");
  EXPECT_FALSE(fs::exists(outside + "/target.g2o"));
  EXPECT_FALSE(fs::exists(outside + "/x.g2o"));
  EXPECT_FALSE(fs::exists(fs::path(dir).parent_path() / "x.g2o"));
  std::set<std::string> names;
  for (const auto& e : fs::directory_iterator(dir)) names.insert(e.path().filename().string());
  EXPECT_EQ(names, (std::set<std::string>{"foreign.g2o", "link.g2o", "ok.g2o"}));
  const auto back = std::get<PoseGraph2>(readPoseGraphFile(dir + "/ok.g2o"));
  EXPECT_EQ(back.numEdges(), 10);
  fs::remove_all(dir);
  fs::remove_all(outside);
}

TEST(ServeFaults, AFloodOfSendersIsBoundedAndCounted) {
  const PoseGraph2 graph = smallGraph();
  lcm::LCM lcm("memq://");
  ServeOptions options;
  options.max_senders = 8;
  Service service(lcm, options);
  Collector collector(lcm, service.channels());
  service.start();
  constexpr int kSenders = 500;
  for (int sender = 1; sender <= kSenders; ++sender) {
    publish(lcm, service.channels().edges, edgeBytes(streamEdge(graph, 0, 1, sender)));
  }
  sendCommand(lcm, service, command_t::STATUS);
  ASSERT_TRUE(
      collector.waitStatus([](const status_t& s) { return s.received == kSenders; }, kGuard));
  service.stop();
  const status_t s = service.status();
  // The least recently heard sender's table makes room: the tables stay 8, nobody is refused.
  EXPECT_EQ(s.senders, 8);
  EXPECT_EQ(s.refused_senders, 0);
  const IntakeCounts& intake = service.summary().intake;
  EXPECT_EQ(intake.senders_evicted, kSenders - 8);
  EXPECT_EQ(intake.accepted, kSenders);
  EXPECT_EQ(intake.rejected, 0);
}

TEST(ServeFaults, OversizeMessagesAreRefusedBeforeDecodingAndGoodOnesStillApplied) {
  const PoseGraph2 graph = smallGraph();
  lcm::LCM lcm("memq://");
  ServeOptions options;
  options.max_queued_commands = 4;
  Service service(lcm, options);
  Collector collector(lcm, service.channels());
  service.start();
  // A valid edge's bytes padded past the limit: it would decode, so only the size refuses it.
  std::vector<std::uint8_t> big = edgeBytes(graph, replayOrder(graph)[0], 1);
  big.resize(options.message_limits.edge + 1, 0);
  publish(lcm, service.channels().edges, big);
  publish(lcm, service.channels().priors,
          std::vector<std::uint8_t>(options.message_limits.prior + 1));
  publish(lcm, service.channels().edge_commands,
          std::vector<std::uint8_t>(options.message_limits.edge_command + 1));
  publish(lcm, service.channels().command,
          std::vector<std::uint8_t>(options.message_limits.command + 1));
  streamEdges(lcm, service, graph, 20);
  ASSERT_TRUE(collector.waitCovered(20, kGuard));
  sendCommand(lcm, service, command_t::STATUS);
  ASSERT_TRUE(
      collector.waitStatus([](const status_t& s) { return s.refused_oversize == 4; }, kGuard));
  service.stop();
  const status_t s = service.status();
  EXPECT_EQ(reasonCount(s, "oversize"), 1);
  EXPECT_EQ(reasonCount(s, "prior oversize"), 1);
  EXPECT_EQ(reasonCount(s, "command oversize"), 1);
  EXPECT_EQ(reasonCount(s, "control oversize"), 1);
  EXPECT_EQ(s.received, 21);
  EXPECT_EQ(s.applied, 20);
}

// The journal of a stopped service: the edges it holds (by seq) and the measurements its update
// marks cover.
struct JournalView {
  std::vector<std::int64_t> edge_seqs;
  std::int64_t marked = 0;
  bool whole = false;  ///< every byte is a complete event
};
JournalView viewJournal(const std::string& path) {
  JournalView v;
  const EventLogContents log = readEventLog(path);
  v.whole = log.damaged.empty() && log.valid_bytes == log.file_bytes;
  for (const auto& e : log.events) {
    edge_t m;
    journal_mark_t mark;
    const int size = static_cast<int>(e.data.size());
    if (decodeMessage(e.data.data(), size, &m) == MessageProblem::kNone) {
      v.edge_seqs.push_back(m.seq);
    } else if (decodeMessage(e.data.data(), size, &mark) == MessageProblem::kNone &&
               mark.kind == journal_mark_t::UPDATE) {
      v.marked += mark.edges;
    }
  }
  return v;
}

// Streams the whole graph into a service whose journal fills up, then restarts from that
// journal: write-ahead holds (every applied edge is in the journal, under a mark), the refused
// ones are counted, the service never stops, and the replay reproduces the estimate exactly.
void expectFullJournalKeepsWriteAhead(const std::string& journal, std::int64_t max_bytes) {
  const PoseGraph2 graph = smallGraph();
  const auto edges = static_cast<std::int64_t>(replayOrder(graph).size());
  ServeOptions options;
  options.journal_path = journal;
  options.journal_max_bytes = max_bytes;
  options.refine_on_exit = false;
  std::ostringstream log;
  options.log = &log;
  Estimate live;
  ServeSummary summary;
  status_t last;
  {
    lcm::LCM lcm("memq://");
    Service service(lcm, options);
    Collector collector(lcm, service.channels());
    service.start();
    streamEdges(lcm, service, graph, static_cast<size_t>(edges));
    sendCommand(lcm, service, command_t::STATUS);
    ASSERT_TRUE(collector.waitStatus(
        [&](const status_t& s) { return s.received == edges && s.queue_depth == s.held; }, kGuard));
    service.stop();
    summary = service.summary();
    last = service.status();
    live = summary.final_estimate;
  }
  EXPECT_GT(last.journal_refused, 0) << "the journal never filled: lower its size";
  EXPECT_EQ(last.journal_refused, reasonCount(last, "journal"));
  EXPECT_EQ(last.accepted + last.rejected, edges);
  EXPECT_EQ(last.rejected, last.journal_refused);
  const JournalView view = viewJournal(journal);
  EXPECT_TRUE(view.whole) << "a refused write left part of an event in the journal";
  EXPECT_EQ(static_cast<std::int64_t>(view.edge_seqs.size()), last.accepted);
  EXPECT_EQ(view.marked, summary.applied);  // every applied edge is journaled, under a mark
  EXPECT_EQ(summary.applied + summary.held_at_stop, last.accepted);
  ASSERT_GT(summary.applied, 0) << log.str();
  // The restart replays the journal to exactly the estimate the live service had.
  lcm::LCM lcm("memq://");
  ServeOptions again = options;
  again.journal_max_bytes = 0;
  Service service(lcm, again);
  Collector collector(lcm, service.channels());
  service.start();
  ASSERT_TRUE(collector.waitFull(1, kGuard));
  const estimate_t replayed = collector.fullEstimates().front();
  service.stop();
  EXPECT_EQ(replayed.ids, live.ids);
  EXPECT_EQ(replayed.translation, live.translation);
  EXPECT_EQ(replayed.rotation, live.rotation);
}

TEST(ServeFaults, JournalAtItsSizeLimitRefusesEdgesAndReplaysExactly) {
  const std::string dir = tempDir("journal_limit");
  expectFullJournalKeepsWriteAhead(dir + "/journal.lcmlog", 30000);
  fs::remove_all(dir);
}

// A small tmpfs in a mount namespace of this test process's own (it dies with the process).
// "" when mounted, else why not.
std::string mountSmallTmpfs(const std::string& dir, const std::string& size) {
  if (::unshare(CLONE_NEWNS) != 0) {
    const int uid = static_cast<int>(::getuid()), gid = static_cast<int>(::getgid());
    if (::unshare(CLONE_NEWUSER | CLONE_NEWNS) != 0) {
      return std::string("unshare(CLONE_NEWNS): ") + std::strerror(errno);
    }
    std::ofstream("/proc/self/setgroups") << "deny";
    std::ofstream("/proc/self/uid_map") << "0 " << uid << " 1";
    std::ofstream("/proc/self/gid_map") << "0 " << gid << " 1";
  }
  if (::mount("none", "/", nullptr, MS_REC | MS_PRIVATE, nullptr) != 0) {
    return std::string("mount --make-rprivate /: ") + std::strerror(errno);
  }
  if (::mount("arbor_test", dir.c_str(), "tmpfs", 0, ("size=" + size).c_str()) != 0) {
    return std::string("mount -t tmpfs: ") + std::strerror(errno);
  }
  return "";
}

TEST(ServeFaults, JournalOnAFullDiskRefusesEdgesAndReplaysExactly) {
  const std::string dir = tempDir("journal_tmpfs");
  const std::string problem = mountSmallTmpfs(dir, "32k");  // 16k of it the marks' reserve
  if (!problem.empty()) {
    fs::remove_all(dir);
    GTEST_SKIP() << "cannot mount a small tmpfs here (" << problem
                 << "); the size-limit test covers the policy";
  }
  expectFullJournalKeepsWriteAhead(dir + "/journal.lcmlog", 0);
  ::umount(dir.c_str());
  fs::remove_all(dir);
}

TEST(LinkWatch, ABorrowedInstanceIsUpOnceItsProbeComesBack) {
  lcm::LCM lcm("memq://");
  LinkWatchOptions options;
  options.probe_channel = "TEST_LINK_PROBE";
  LinkWatch link(lcm, options);
  int messages = 0;
  link.subscribe("TEST_CHANNEL",
                 [&](const lcm::ReceiveBuffer*, const std::string&) { ++messages; });
  EXPECT_FALSE(link.up());
  for (int k = 0; k < 600 && !link.up(); ++k) link.handle(100);
  EXPECT_TRUE(link.up());
  const char byte = 1;
  lcm.publish("TEST_CHANNEL", &byte, 1);
  for (int k = 0; k < 600 && messages == 0; ++k) link.handle(100);
  EXPECT_EQ(messages, 1);
  EXPECT_EQ(link.counts().outages, 0);
}

}  // namespace
}  // namespace arbor::serve
