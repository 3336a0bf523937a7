// The streaming core without a transport (tools/serve/streaming_core.h): an in-memory adapter
// hands measurements straight to StreamingCore::receive() and keeps what the core publishes, an
// in-memory journal implements JournalSink. Driven so, the core gives the LCM service's estimate
// bit for bit on the same stream (lockstep over memq://), a restart from the in-memory journal
// reproduces the estimate bit for bit with the seq state rebuilt, and the LCM service's event-log
// journal replays in the memory-driven core to the LCM run's estimate: one core, two adapters.
#include <algorithm>
#include <condition_variable>
#include <cstdint>
#include <cstdio>
#include <cstring>
#include <fstream>
#include <iterator>
#include <map>
#include <memory>
#include <mutex>
#include <random>
#include <sstream>
#include <string>
#include <thread>
#include <vector>

#include <gtest/gtest.h>

#include "arbor_slam/io/lcm_journal.h"
#include "arbor_slam/tests/lcm_test_support.h"
#include "arbor_slam/tests/memory_journal.h"
#include "arbor_slam/tools/serve/journal_sink.h"
#include "arbor_slam/tools/serve/lcm_event_journal.h"
#include "arbor_slam/tools/serve/serve_service.h"
#include "arbor_slam/tools/serve/streaming_core.h"

namespace arbor::serve {
namespace {

using testing::Collector;
using testing::edgeBytes;
using testing::replayOrder;
using testing::streamEdge;

constexpr double kGuardS = 60;  // a failure guard only

/// The outbound side of a transport kept in memory: every estimate and status the core
/// publishes, and a wait for the estimate covering an edge's seq.
class MemoryPublisher final : public Publisher {
 public:
  void publishEstimate(const Estimate& e) override {
    std::lock_guard<std::mutex> lock(mutex_);
    if (e.full) full_.push_back(e);
    all_.push_back(e);
    last_seq_ = std::max(last_seq_, e.last_seq);
    ++estimates_;
    cv_.notify_all();
  }
  void publishStatus(const CoreStatus& s) override {
    std::lock_guard<std::mutex> lock(mutex_);
    status_ = s;
    ++statuses_;
  }
  void publishCovariance(const CovarianceAnswer&) override {}
  bool waitCovered(std::int64_t seq) {
    std::unique_lock<std::mutex> lock(mutex_);
    return cv_.wait_for(lock, std::chrono::duration<double>(kGuardS),
                        [&] { return last_seq_ >= seq; });
  }
  std::vector<Estimate> full() {
    std::lock_guard<std::mutex> lock(mutex_);
    return full_;
  }
  int estimates() {
    std::lock_guard<std::mutex> lock(mutex_);
    return estimates_;
  }
  std::vector<Estimate> all() {
    std::lock_guard<std::mutex> lock(mutex_);
    return all_;
  }

 private:
  std::mutex mutex_;
  std::condition_variable cv_;
  std::vector<Estimate> full_, all_;
  std::int64_t last_seq_ = 0;
  int estimates_ = 0;
  int statuses_ = 0;
  CoreStatus status_;
};

/// An edge as the in-memory transport hands it over: typed, no bytes, z carried as the pose
/// fields x y θ (as every transport carries a pose: the LCM path's z is SE2(x, y, θ) too); its
/// fingerprint is the FNV-1a of its fields (what identifies the message for this transport).
Arrival memoryArrival(StreamEdge<SE2> e) {
  double t[3], r[4];
  poseToFields(e.z, t, r);
  e.z = poseFromFields<SE2>(t, r);
  Arrival a;
  a.kind = MeasurementKind::kEdge;
  a.edge = e;
  std::vector<double> fields = {static_cast<double>(e.sender),
                                static_cast<double>(e.seq),
                                static_cast<double>(e.from),
                                static_cast<double>(e.to),
                                e.z.x(),
                                e.z.y(),
                                e.z.angle()};
  for (int r = 0; r < 3; ++r)
    for (int c = 0; c < 3; ++c) fields.push_back(e.omega(r, c));
  a.fingerprint = EdgeIntake::fingerprint(fields.data(), static_cast<int>(fields.size() * 8));
  return a;
}

PoseGraph2 graph() { return testing::manhattanGraph(120, 4, -1, 11); }

void expectBitForBit(const Estimate& a, const Estimate& b) {
  ASSERT_EQ(a.num_poses, b.num_poses);
  ASSERT_GT(a.num_poses, 0);
  EXPECT_EQ(a.ids, b.ids);
  EXPECT_EQ(a.translation, b.translation);
  EXPECT_EQ(a.rotation, b.rotation);
}

/// edges [first, last) of `order` in lockstep through the memory adapter (seq = position + 1).
void feedMemory(StreamingCore& core, MemoryPublisher& out, const PoseGraph2& g,
                const std::vector<int>& order, size_t first, size_t last) {
  for (size_t k = first; k < last; ++k) {
    const auto seq = static_cast<std::int64_t>(k) + 1;
    core.receive(memoryArrival(streamEdge(g, order[k], seq)));
    ASSERT_TRUE(out.waitCovered(seq)) << "edge " << k;
  }
}

/// The LCM service on the same edges in lockstep over memq://; its final estimate.
Estimate lcmRun(const PoseGraph2& g, const std::vector<int>& order, const std::string& journal) {
  lcm::LCM lcm("memq://");
  EXPECT_TRUE(lcm.good());
  ServeOptions options;
  options.journal_path = journal;
  Service service(lcm, options);
  Collector collector(lcm, service.channels());
  service.start();
  for (size_t k = 0; k < order.size(); ++k) {
    const auto seq = static_cast<std::int64_t>(k) + 1;
    const auto bytes = edgeBytes(g, order[k], seq);
    lcm.publish(service.channels().edges, bytes.data(), static_cast<unsigned>(bytes.size()));
    EXPECT_TRUE(collector.waitCovered(seq, kGuardS)) << "edge " << k;
  }
  service.stop();
  EXPECT_EQ(service.summary().applied, static_cast<std::int64_t>(order.size()));
  return service.summary().final_estimate;
}

TEST(StreamingCore, InMemoryAdapterGivesTheLcmServicesEstimateBitForBit) {
  const PoseGraph2 g = graph();
  const std::vector<int> order = replayOrder(g);
  const Estimate over_lcm = lcmRun(g, order, "");

  MemoryPublisher out;
  auto entries = std::make_shared<std::vector<JournalEntry>>();
  StreamingCore core(out, std::make_unique<MemoryJournal>(entries), StreamingOptions{});
  core.start();
  feedMemory(core, out, g, order, 0, order.size());
  core.stop();
  const ServeSummary& s = core.summary();
  EXPECT_EQ(s.applied, static_cast<std::int64_t>(order.size()));
  EXPECT_EQ(s.updates, static_cast<std::int64_t>(order.size()));  // one update per edge
  EXPECT_EQ(s.intake.gaps, 0);
  EXPECT_EQ(out.estimates(), static_cast<int>(order.size()) + 1);  // + the final one
  expectBitForBit(s.final_estimate, over_lcm);
  EXPECT_EQ(s.F_final, over_lcm.F);
  // Write-ahead through the seam: every edge, then a mark per update and the exit refinement's.
  int measurements = 0, marks = 0, refines = 0;
  for (const JournalEntry& e : *entries) {
    measurements += e.type == JournalEntry::Type::kMeasurement;
    marks += e.type == JournalEntry::Type::kUpdateMark;
    refines += e.type == JournalEntry::Type::kRefineMark;
  }
  EXPECT_EQ(measurements, static_cast<int>(order.size()));
  EXPECT_EQ(marks, static_cast<int>(order.size()));
  EXPECT_EQ(refines, 1);
}

// --solve-budget-mb: the budget leaves cliques deferred after an update; the idle core solves
// them and publishes the poses they moved, so a subscriber that applies every changed-poses
// estimate holds the core's estimate bit for bit.
TEST(StreamingCore, WithASolveBudgetTheIdleCoreSolvesTheBacklogAndPublishesWhatItMoved) {
  const PoseGraph2 g = graph();
  const std::vector<int> order = replayOrder(g);
  StreamingOptions options;
  options.refine_on_exit = false;  // the live estimate at stop
  options.smoother.solve_budget_mb = 0.0002;
  MemoryPublisher out;
  StreamingCore core(out, nullptr, options);
  core.start();
  feedMemory(core, out, g, order, 0, order.size());
  // Estimates beyond one per update: the idle drains published too.
  const auto deadline = std::chrono::steady_clock::now() + std::chrono::seconds(10);
  while (out.estimates() <= static_cast<int>(order.size()) &&
         std::chrono::steady_clock::now() < deadline)
    std::this_thread::sleep_for(std::chrono::milliseconds(5));
  EXPECT_GT(out.estimates(), static_cast<int>(order.size()));
  // Then idle: no estimate for 300 ms (the backlog solved). What was published up to here,
  // without stop()'s full estimate, must be the live estimate.
  for (int seen = -1; seen != out.estimates() && std::chrono::steady_clock::now() < deadline;) {
    seen = out.estimates();
    std::this_thread::sleep_for(std::chrono::milliseconds(300));
  }
  const std::vector<Estimate> published = out.all();
  core.stop();
  std::map<std::int64_t, std::pair<std::vector<double>, std::vector<double>>> view;
  for (const Estimate& e : published)
    for (int k = 0; k < e.num_poses; ++k) view[e.ids[k]] = {e.translation[k], e.rotation[k]};
  const Estimate& live = core.summary().final_estimate;
  ASSERT_GT(live.num_poses, 0);
  ASSERT_EQ(view.size(), static_cast<size_t>(live.num_poses));
  for (int k = 0; k < live.num_poses; ++k) {
    EXPECT_EQ(view[live.ids[k]].first, live.translation[k]) << "pose " << live.ids[k];
    EXPECT_EQ(view[live.ids[k]].second, live.rotation[k]) << "pose " << live.ids[k];
  }
}

TEST(StreamingCore, RestartFromTheInMemoryJournalReproducesTheEstimateBitForBit) {
  const PoseGraph2 g = graph();
  const std::vector<int> order = replayOrder(g);
  const size_t half = order.size() / 2;
  auto entries = std::make_shared<std::vector<JournalEntry>>();
  StreamingOptions options;
  options.refine_on_exit = false;  // the live estimate at the kill point
  Estimate live;
  {
    MemoryPublisher out;
    StreamingCore core(out, std::make_unique<MemoryJournal>(entries), options);
    core.start();
    feedMemory(core, out, g, order, 0, half);
    core.stop();
    live = core.summary().final_estimate;
  }
  MemoryPublisher out;
  StreamingCore core(out, std::make_unique<MemoryJournal>(entries), options);
  core.start();  // replays: the first full estimate published is the journal's
  ASSERT_FALSE(out.full().empty());
  expectBitForBit(out.full().front(), live);
  // The seq state came back with it: a repeat of seq 1 is a duplicate, the rest no gap.
  core.receive(memoryArrival(streamEdge(g, order[0], 1)));
  feedMemory(core, out, g, order, half, order.size());
  core.stop();
  const ServeSummary& s = core.summary();
  EXPECT_EQ(s.journal_edges, static_cast<std::int64_t>(half));
  EXPECT_EQ(s.applied, static_cast<std::int64_t>(order.size()));
  EXPECT_EQ(s.intake.duplicates, 1);
  EXPECT_EQ(s.intake.gaps, 0);
}

TEST(StreamingCore, TheLcmEventJournalReplaysInTheMemoryDrivenCore) {
  const PoseGraph2 g = graph();
  const std::vector<int> order = replayOrder(g);
  const std::string path = testing::tempPath("arbor_streaming_core", "journal.lcmlog");
  const Estimate over_lcm = lcmRun(g, order, path);
  MemoryPublisher out;
  StreamingOptions options;
  options.refine_on_exit = false;
  StreamingCore core(
      out,
      std::make_unique<LcmEventJournal>(path, Channels::withPrefix(""), EventLogWriterOptions{}),
      options);
  core.start();
  ASSERT_FALSE(out.full().empty());
  expectBitForBit(out.full().front(), over_lcm);  // its updates and its exit refinement
  core.stop();
  EXPECT_EQ(core.summary().journal_edges, static_cast<std::int64_t>(order.size()));
  std::remove(path.c_str());
}

/// A publisher that holds the smoother thread in its first estimate until opened: the thread
/// takes nothing from the backlog meanwhile.
class GatedPublisher final : public Publisher {
 public:
  void publishEstimate(const Estimate& e) override {
    std::unique_lock<std::mutex> lock(mutex_);
    entered_ = true;
    cv_.notify_all();
    cv_.wait(lock, [&] { return open_; });
    last_seq_ = std::max(last_seq_, e.last_seq);
    cv_.notify_all();
  }
  void publishStatus(const CoreStatus&) override {}
  void publishCovariance(const CovarianceAnswer&) override {}
  bool waitEntered() {
    std::unique_lock<std::mutex> lock(mutex_);
    return cv_.wait_for(lock, std::chrono::duration<double>(kGuardS), [&] { return entered_; });
  }
  void open() {
    std::lock_guard<std::mutex> lock(mutex_);
    open_ = true;
    cv_.notify_all();
  }
  bool waitCovered(std::int64_t seq) {
    std::unique_lock<std::mutex> lock(mutex_);
    return cv_.wait_for(lock, std::chrono::duration<double>(kGuardS),
                        [&] { return last_seq_ >= seq; });
  }

 private:
  std::mutex mutex_;
  std::condition_variable cv_;
  bool entered_ = false, open_ = false;
  std::int64_t last_seq_ = 0;
};

// Issue 56: the receive backlog is bounded. While the smoother thread is held, a burst larger
// than max_backlog leaves max_backlog waiting; the rest is dropped unread and counted, never
// journaled; everything journaled is applied, and what was dropped, sent again, is applied once.
TEST(StreamingCore, TheReceiveBacklogIsBoundedAndWhatItDropsIsCountedNeverJournaled) {
  const PoseGraph2 g = graph();
  const std::vector<int> order = replayOrder(g);
  const auto n = static_cast<std::int64_t>(order.size());
  ASSERT_GT(n, 100);
  StreamingOptions options;
  options.refine_on_exit = false;
  options.max_backlog = 20;
  auto entries = std::make_shared<std::vector<JournalEntry>>();
  GatedPublisher out;
  StreamingCore core(out, std::make_unique<MemoryJournal>(entries), options);
  core.start();
  auto edge = [&](std::int64_t seq) {
    return memoryArrival(streamEdge(g, order[static_cast<size_t>(seq - 1)], seq));
  };
  core.receive(edge(1));
  ASSERT_TRUE(out.waitEntered());  // the smoother thread holds edge 1's update
  size_t most = 0;
  for (std::int64_t seq = 2; seq <= n; ++seq) {
    core.receive(edge(seq));
    most = std::max(most, core.backlog());
  }
  EXPECT_EQ(most, options.max_backlog);
  const std::int64_t kept = 1 + static_cast<std::int64_t>(options.max_backlog);
  out.open();
  ASSERT_TRUE(out.waitCovered(kept));
  // What was dropped, sent again (as loss recovery asks for it): accepted and applied once.
  for (std::int64_t seq = kept + 1; seq <= n; ++seq) {
    core.receive(edge(seq));
    ASSERT_TRUE(out.waitCovered(seq)) << "edge " << seq;
  }
  core.stop();
  const ServeSummary& s = core.summary();
  EXPECT_EQ(s.backlog_dropped, n - kept);
  EXPECT_EQ(s.intake.accepted, n);
  EXPECT_EQ(s.intake.duplicates, 0);
  EXPECT_EQ(s.applied, n);
  EXPECT_EQ(s.held_at_stop, 0);
  std::int64_t journaled = 0;
  for (const JournalEntry& e : *entries)
    if (e.type == JournalEntry::Type::kMeasurement) ++journaled;
  EXPECT_EQ(journaled, n);
}

/// Streams the graph through a memory-driven core with a journal and stops it (its exit
/// refinement as `options` say); the summary, and the journal in `entries`.
ServeSummary runWithJournal(const StreamingOptions& options,
                            const std::shared_ptr<std::vector<JournalEntry>>& entries) {
  const PoseGraph2 g = graph();
  const std::vector<int> order = replayOrder(g);
  MemoryPublisher out;
  StreamingCore core(out, std::make_unique<MemoryJournal>(entries), options);
  core.start();
  feedMemory(core, out, g, order, 0, order.size());
  core.stop();
  return core.summary();
}

/// A restart from `entries` without an exit refinement of its own: its first full estimate.
Estimate restartFrom(const std::shared_ptr<std::vector<JournalEntry>>& entries,
                     StreamingOptions options) {
  options.refine_on_exit = false;
  MemoryPublisher out;
  StreamingCore core(out, std::make_unique<MemoryJournal>(entries), options);
  core.start();
  core.stop();
  EXPECT_FALSE(out.full().empty());
  return out.full().empty() ? Estimate() : out.full().front();
}

// stop()'s refinement cut after its first iteration (the token's countdown: no clock) ends
// short of the full one, says so, and journals the cut after it ran, so that a restart repeats
// exactly that refinement: bit for bit the cut estimate, not the converged one.
TEST(StreamingCore, AnExitRefinementCutShortIsJournaledAndRepeatedByARestart) {
  for (const bool robust : {false, true}) {
    SCOPED_TRACE(robust ? "robust" : "plain");
    StreamingOptions options;
    if (robust) options.robust = RobustOptions{};
    auto full_entries = std::make_shared<std::vector<JournalEntry>>();
    const ServeSummary full = runWithJournal(options, full_entries);
    EXPECT_FALSE(full.exit_refine_cut);
    ASSERT_GE(full.exit_refine_iterations, 2);  // else a cut after one would change nothing
    ASSERT_EQ(full_entries->back().type, JournalEntry::Type::kRefineMark);
    EXPECT_EQ(full_entries->back().measurements, 0);  // to convergence

    StreamingOptions cut_options = options;
    cut_options.exit_refine_cancel = CancellationToken();
    const int checks = 1;  // one relinearise-all iteration (no closure graduates here)
    cut_options.exit_refine_cancel.cancelAfterChecks(checks);
    auto cut_entries = std::make_shared<std::vector<JournalEntry>>();
    const ServeSummary cut = runWithJournal(cut_options, cut_entries);
    EXPECT_TRUE(cut.exit_refine_cut);
    EXPECT_LT(cut.exit_refine_iterations, full.exit_refine_iterations);
    ASSERT_EQ(cut_entries->back().type, JournalEntry::Type::kRefineMark);
    EXPECT_EQ(cut_entries->back().measurements, checks + 1);
    EXPECT_NE(cut.final_estimate.translation, full.final_estimate.translation);
    EXPECT_GE(cut.F_final, full.F_final * (1 - 1e-12));

    expectBitForBit(restartFrom(cut_entries, options), cut.final_estimate);
    expectBitForBit(restartFrom(full_entries, options), full.final_estimate);
  }
}

// A budget of 0 s: the watchdog cancels at once, and whether the refinement saw it before its
// first iteration or after some is the scheduler's; either way the journal says which, and a
// restart repeats it bit for bit.
TEST(StreamingCore, AnExitRefinementOverItsBudgetIsRepeatedByARestart) {
  StreamingOptions options;
  options.exit_refine_budget_s = 0;
  auto entries = std::make_shared<std::vector<JournalEntry>>();
  const ServeSummary s = runWithJournal(options, entries);
  ASSERT_EQ(entries->back().type, JournalEntry::Type::kRefineMark);
  EXPECT_EQ(entries->back().measurements > 0, s.exit_refine_cut);
  expectBitForBit(restartFrom(entries, StreamingOptions{}), s.final_estimate);
}

std::vector<char> fileBytes(const std::string& path) {
  std::ifstream in(path, std::ios::binary);
  return {std::istreambuf_iterator<char>(in), std::istreambuf_iterator<char>()};
}

void writeFile(const std::string& path, const std::vector<char>& bytes) {
  std::ofstream out(path, std::ios::binary | std::ios::trunc);
  out.write(bytes.data(), static_cast<std::streamsize>(bytes.size()));
}

/// A restart on the LCM event journal at `path` without an exit refinement of its own.
struct Restart {
  Estimate first;  ///< the first full estimate published: the journal's
  ServeSummary summary;
};
Restart restartOnFile(const std::string& path, std::ostream* log = nullptr) {
  StreamingOptions options;
  options.refine_on_exit = false;
  options.log = log;
  MemoryPublisher out;
  StreamingCore core(
      out,
      std::make_unique<LcmEventJournal>(path, Channels::withPrefix(""), EventLogWriterOptions{}),
      options);
  core.start();
  core.stop();
  Restart r;
  if (!out.full().empty()) r.first = out.full().front();
  r.summary = core.summary();
  return r;
}

// Issue 56: damage to the journal (a changed seq, a length of 0x7FFFFFFF, junk after the exit
// refinement's mark, random changed bytes and cuts) costs exactly the damaged events: a restart
// on the damaged journal gives bit for bit the estimate (and F) of a restart on the journal
// with those events removed, and counts them.
TEST(StreamingCore, ADamagedJournalReplaysAsTheJournalWithoutTheDamagedEvents) {
  const PoseGraph2 g = graph();
  const std::vector<int> order = replayOrder(g);
  const std::string path = testing::tempPath("arbor_streaming_core", "damage.lcmlog");
  const std::string damaged_path = path + ".damaged";
  const std::string reference_path = path + ".reference";
  {
    MemoryPublisher out;
    StreamingCore core(
        out,
        std::make_unique<LcmEventJournal>(path, Channels::withPrefix(""), EventLogWriterOptions{}),
        StreamingOptions{});  // with the exit refinement: its mark is the last event
    core.start();
    feedMemory(core, out, g, order, 0, order.size());
    core.stop();
  }
  const std::vector<char> clean = fileBytes(path);
  const EventLogContents log = readEventLog(path);
  ASSERT_EQ(log.valid_bytes, static_cast<std::int64_t>(clean.size()));
  ASSERT_EQ(log.events.back().channel, kJournalMarkChannel);
  const auto n = static_cast<int>(log.events.size());
  const auto start = [&](int k) { return log.events[static_cast<size_t>(k)].offset; };
  const auto end = [&](int k) {
    return k + 1 < n ? start(k + 1) : static_cast<std::int64_t>(clean.size());
  };
  const auto dataAt = [&](int k) {
    return static_cast<size_t>(
        start(k) + 28 +
        static_cast<std::int64_t>(log.events[static_cast<size_t>(k)].channel.size()));
  };
  std::vector<int> edges;  // events holding an edge
  for (int k = 0; k < n; ++k)
    if (log.events[static_cast<size_t>(k)].channel == Channels::withPrefix("").edges)
      edges.push_back(k);
  ASSERT_EQ(edges.size(), order.size());
  const Restart clean_restart = restartOnFile(path);

  // `damaged` must cost exactly the events `lost` (`events`: how many counted damaged, or −1
  // where the damage is the tail's).
  const auto check = [&](const std::string& what, const std::vector<char>& damaged,
                         const std::vector<int>& lost, std::int64_t events) {
    SCOPED_TRACE(what);
    std::vector<char> reference;
    for (int k = 0; k < n; ++k)
      if (std::find(lost.begin(), lost.end(), k) == lost.end())
        reference.insert(reference.end(), clean.begin() + start(k), clean.begin() + end(k));
    writeFile(damaged_path, damaged);
    writeFile(reference_path, reference);
    const Restart a = restartOnFile(damaged_path);
    const Restart b = restartOnFile(reference_path);
    expectBitForBit(a.first, b.first);
    expectBitForBit(a.summary.final_estimate, b.summary.final_estimate);
    EXPECT_EQ(a.summary.F_final, b.summary.F_final);
    EXPECT_EQ(a.summary.journal_edges, b.summary.journal_edges);
    EXPECT_EQ(b.summary.journal_damaged.events, 0);
    if (events >= 0) {
      EXPECT_EQ(a.summary.journal_damaged.events, events);
    }
    return a;
  };

  // Seq 2^56 + seq (its high byte changed): the edge alone is lost, the later ones replayed.
  {
    const int k = edges[edges.size() / 2];
    std::vector<char> b = clean;
    b[dataAt(k) + 24] ^= 1;  // edge_t: hash, utime, sender, seq
    const Restart r = check("seq", b, {k}, 1);
    EXPECT_EQ(r.summary.journal_edges, static_cast<std::int64_t>(order.size()) - 1);
    std::ostringstream log_lines;  // the place and the values, in one line
    restartOnFile(damaged_path, &log_lines);
    const std::string line = "bytes " + std::to_string(start(k)) + " to " + std::to_string(end(k)) +
                             " are damaged (at byte " + std::to_string(start(k)) + ": checksum 0x";
    EXPECT_NE(log_lines.str().find(line), std::string::npos) << log_lines.str();
  }
  // A data length of 0x7FFFFFFF.
  {
    const int k = edges[edges.size() / 3];
    std::vector<char> b = clean;
    for (int i = 0; i < 4; ++i)
      b[static_cast<size_t>(start(k) + 24 + i)] = i == 0 ? '\x7f' : '\xff';
    check("length", b, {k}, 1);
  }
  // Junk after the exit refinement's mark: the mark is kept, the restart is the clean one.
  std::mt19937 rng(56);
  for (const int size : {4, 3000}) {
    std::vector<char> b = clean;
    for (int i = 0; i < size; ++i) b.push_back(static_cast<char>(rng()));
    const Restart r = check("junk of " + std::to_string(size) + " bytes", b, {}, 0);
    expectBitForBit(r.first, clean_restart.first);
    EXPECT_EQ(r.summary.journal_damaged.tail_bytes, size);
  }
  // Changed bytes anywhere and cuts anywhere.
  for (int trial = 0; trial < 8; ++trial) {
    std::vector<char> b = clean;
    const auto at = static_cast<std::int64_t>(rng() % b.size());
    b[static_cast<size_t>(at)] = static_cast<char>(b[static_cast<size_t>(at)] ^ (1 + rng() % 255));
    int k = 0;
    while (end(k) <= at) ++k;
    check("byte " + std::to_string(at), b, {k}, k + 1 < n ? 1 : -1);
  }
  for (int trial = 0; trial < 4; ++trial) {
    const auto length = static_cast<std::int64_t>(rng() % clean.size());
    std::vector<int> lost;
    for (int k = 0; k < n; ++k)
      if (end(k) > length) lost.push_back(k);
    check("cut at " + std::to_string(length),
          std::vector<char>(clean.begin(), clean.begin() + length), lost, 0);
  }
  // The same journal as an older arbor wrote it (event numbers 0, 1, 2, …: no checksums):
  // replayed as before, unchecked, counted and said so.
  {
    std::vector<char> b = clean;
    for (int k = 0; k < n; ++k)
      for (int i = 0; i < 8; ++i)
        b[static_cast<size_t>(start(k) + 4 + i)] =
            static_cast<char>(i < 4 ? 0 : k >> (8 * (7 - i)));
    writeFile(damaged_path, b);
    std::ostringstream log_lines;
    const Restart r = restartOnFile(damaged_path, &log_lines);
    expectBitForBit(r.first, clean_restart.first);
    EXPECT_EQ(r.summary.journal_damaged.unchecked, n);
    EXPECT_EQ(r.summary.journal_damaged.events, 0);
    EXPECT_NE(log_lines.str().find("the first " + std::to_string(n) +
                                   " events were written before events carried checksums"),
              std::string::npos)
        << log_lines.str();
  }
  std::remove(path.c_str());
  std::remove(damaged_path.c_str());
  std::remove(reference_path.c_str());
}

}  // namespace
}  // namespace arbor::serve
