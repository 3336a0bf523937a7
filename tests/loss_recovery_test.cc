// Loss recovery's parts (docs/lcm.md, "Loss recovery"): resend_t's checked decoding, serve's
// GapTracker (the reorder buffer and its requests), the publisher's ResendWindow, and the
// streaming core with them: edges that arrive after a gap are applied in seq order once the
// gap is resent, a resent copy is a duplicate, and a restart on the journal asks for nothing it
// applied. tests/lcm_lossy_test.cc runs the whole over a lossy link.
#include <chrono>
#include <condition_variable>
#include <cstdint>
#include <memory>
#include <mutex>
#include <thread>
#include <vector>

#include <gtest/gtest.h>

#include "arbor_slam/io/lcm_messages.h"
#include "arbor_slam/tests/lcm_test_support.h"
#include "arbor_slam/tests/memory_journal.h"
#include "arbor_slam/tools/cli/resend_window.h"
#include "arbor_slam/tools/serve/gap_tracker.h"
#include "arbor_slam/tools/serve/serve_service.h"
#include "arbor_slam/tools/serve/streaming_core.h"

namespace arbor::serve {
namespace {

using Clock = std::chrono::steady_clock;
using std::chrono::milliseconds;

// ---- resend_t ----

std::vector<std::uint8_t> resendBytes(const resend_t& m) { return encodeMessage(m); }

resend_t request(std::int64_t settled, std::int64_t highest,
                 std::vector<std::pair<std::int64_t, std::int64_t>> ranges) {
  ResendMessage r;
  r.sender = 3;
  r.settled = settled;
  r.highest = highest;
  r.missing = std::move(ranges);
  return makeResendMessage(r);
}

TEST(ResendMessage, RoundTripsAndRefusesBadFieldsNamingThem) {
  const std::vector<std::uint8_t> ok = resendBytes(request(4, 20, {{5, 6}, {9, 9}, {12, 19}}));
  const ResendDecoding d = decodeResend(ok.data(), static_cast<int>(ok.size()));
  ASSERT_TRUE(d.ok()) << d.detail;
  EXPECT_TRUE(d.message.request);
  EXPECT_FALSE(d.message.priors);
  EXPECT_EQ(d.message.sender, 3);
  EXPECT_EQ(d.message.settled, 4);
  EXPECT_EQ(d.message.highest, 20);
  EXPECT_EQ(d.message.missing.size(), 3u);

  const auto refused = [](const resend_t& m) {
    const std::vector<std::uint8_t> b = encodeMessage(m);
    return decodeResend(b.data(), static_cast<int>(b.size()));
  };
  resend_t m = request(4, 20, {{5, 6}});
  m.kind = 3;
  EXPECT_EQ(refused(m).problem, MessageProblem::kKind);
  EXPECT_NE(refused(m).detail.find("kind 3"), std::string::npos) << refused(m).detail;
  m = request(4, 20, {{5, 6}});
  m.stream = 0;
  EXPECT_EQ(refused(m).problem, MessageProblem::kKind);
  EXPECT_EQ(refused(request(4, 20, {{4, 6}})).problem, MessageProblem::kSeq);   // <= settled
  EXPECT_EQ(refused(request(4, 20, {{5, 20}})).problem, MessageProblem::kSeq);  // >= highest
  EXPECT_EQ(refused(request(4, 20, {{9, 10}, {7, 8}})).problem, MessageProblem::kSeq);
  EXPECT_EQ(refused(request(4, 20, {{9, 8}})).problem, MessageProblem::kSeq);
  EXPECT_EQ(refused(request(21, 20, {})).problem, MessageProblem::kSeq);
  m = request(4, 20, {});
  m.kind = resend_t::WINDOW;
  EXPECT_TRUE(refused(m).ok());
  m = request(4, 20, {{5, 6}});
  m.kind = resend_t::WINDOW;
  EXPECT_EQ(refused(m).problem, MessageProblem::kMalformed);

  // num_ranges is checked before anything is allocated: 65, negative, and a count the bytes
  // cannot hold.
  std::vector<std::uint8_t> b = resendBytes(request(0, 200, {{1, 1}}));
  constexpr int kNumRanges = 42;
  const auto setCount = [&](std::int16_t n) {
    std::vector<std::uint8_t> c = b;
    c[kNumRanges] = static_cast<std::uint8_t>((n >> 8) & 0xff);
    c[kNumRanges + 1] = static_cast<std::uint8_t>(n & 0xff);
    return decodeResend(c.data(), static_cast<int>(c.size()));
  };
  EXPECT_EQ(setCount(65).problem, MessageProblem::kMalformed);
  EXPECT_EQ(setCount(-1).problem, MessageProblem::kMalformed);
  EXPECT_EQ(setCount(64).problem, MessageProblem::kTruncated);
  for (size_t n = 0; n < b.size(); ++n)
    EXPECT_FALSE(decodeResend(b.data(), static_cast<int>(n)).ok()) << n << " bytes";
  ResendMessage many;
  for (int k = 0; k < kMaxResendRanges + 1; ++k) many.missing.emplace_back(2 * k + 1, 2 * k + 1);
  EXPECT_THROW(makeResendMessage(many), std::invalid_argument);
}

// ---- GapTracker ----

IntakeResult accepted(std::int64_t seq, std::int64_t sender = 1) {
  IntakeResult r;
  r.verdict = Intake::kAccepted;
  r.sender = sender;
  r.seq = seq;
  return r;
}

std::vector<std::int64_t> seqs(const std::vector<IntakeResult>& rs) {
  std::vector<std::int64_t> out;
  for (const IntakeResult& r : rs) out.push_back(r.seq);
  return out;
}

using Seqs = std::vector<std::int64_t>;
using Range = std::pair<std::int64_t, std::int64_t>;

TEST(GapTracker, ReleasesInSeqOrderOnceTheGapIsFilled) {
  GapTracker t(milliseconds(1000), 100, 1000);
  const auto now = Clock::now();
  EXPECT_EQ(seqs(t.offer(accepted(1), now)), Seqs({1}));
  EXPECT_EQ(seqs(t.offer(accepted(4), now)), Seqs());
  EXPECT_EQ(seqs(t.offer(accepted(5), now)), Seqs());
  EXPECT_EQ(seqs(t.offer(accepted(3), now)), Seqs());
  EXPECT_EQ(t.counts().held, 3);
  const std::vector<ResendRequest> q = t.requests();
  ASSERT_EQ(q.size(), 1u);
  EXPECT_EQ(q[0].settled, 1);
  EXPECT_EQ(q[0].highest, 5);
  ASSERT_EQ(q[0].missing.size(), 1u);
  EXPECT_EQ(q[0].missing[0], Range(2, 2));
  EXPECT_EQ(seqs(t.offer(accepted(2), now)), Seqs({2, 3, 4, 5}));
  EXPECT_EQ(t.counts().held, 0);
  EXPECT_EQ(t.counts().given_up, 0);
  EXPECT_EQ(t.settled(MeasurementKind::kEdge, 1), 5);
  // Heard (2 arrived): an acknowledgement, then nothing held and nothing heard: no request; a
  // duplicate heard: an acknowledgement again.
  ASSERT_EQ(t.requests().size(), 1u);
  EXPECT_TRUE(t.requests().empty());
  t.heard(MeasurementKind::kEdge, 1, now);
  const std::vector<ResendRequest> ack = t.requests();
  ASSERT_EQ(ack.size(), 1u);
  EXPECT_EQ(ack[0].settled, 5);
  EXPECT_TRUE(ack[0].missing.empty());
}

TEST(GapTracker, OffReleasesEverythingAtOnceAndAsksNothing) {
  GapTracker t(milliseconds(0), 100, 1000);
  EXPECT_EQ(seqs(t.offer(accepted(3), Clock::now())), Seqs({3}));
  EXPECT_TRUE(t.requests().empty());
}

TEST(GapTracker, AGapIsGivenUpAfterTheHoldWhileItsSenderIsHeardPausedWhileQuiet) {
  GapTracker t(milliseconds(1000), 100, 1000);
  const auto t0 = Clock::now();
  t.offer(accepted(1), t0);
  t.offer(accepted(3), t0);
  // Quiet (an outage): 3 s pass, 0.5 s of them count.
  for (int k = 1; k <= 30; ++k) EXPECT_TRUE(t.expire(t0 + milliseconds(100 * k)).empty());
  // Heard again: after the rest of the hold, the gap goes.
  std::vector<IntakeResult> released;
  std::int64_t given_up = 0;
  for (int k = 31; k <= 50 && released.empty(); ++k) {
    const auto now = t0 + milliseconds(100 * k);
    t.heard(MeasurementKind::kEdge, 1, now);
    released = t.expire(now, &given_up);
  }
  EXPECT_EQ(seqs(released), Seqs({3}));
  EXPECT_EQ(given_up, 1);
  EXPECT_EQ(t.counts().gaps_given_up, 1);
  // A late arrival of the given-up seq is released at once (once: the intake judges repeats).
  EXPECT_EQ(seqs(t.offer(accepted(2), t0 + milliseconds(6000))), Seqs({2}));
  EXPECT_EQ(t.counts().late, 1);
  // Quiet for kSilentFactor holds: given up however quiet.
  t.offer(accepted(6), t0 + milliseconds(6000));
  EXPECT_TRUE(t.expire(t0 + milliseconds(6000 + 9900)).empty());
  EXPECT_EQ(seqs(t.expire(t0 + milliseconds(6000 + 10000))), Seqs({6}));
}

TEST(GapTracker, LimitWindowAnswerForgetAndStopGiveUpInOrder) {
  GapTracker t(milliseconds(1000), 3, 50);
  const auto now = Clock::now();
  t.offer(accepted(1), now);
  for (std::int64_t s : {3, 5, 7}) EXPECT_TRUE(t.offer(accepted(s), now).empty());
  // The fourth held message: the oldest gap (2) goes, 3 is released.
  EXPECT_EQ(seqs(t.offer(accepted(9), now)), Seqs({3}));
  // The sender holds nothing at or below 6: 4 and 6 go, 5 and 7 are released.
  EXPECT_EQ(seqs(t.giveUpTo(MeasurementKind::kEdge, 1, 6)), Seqs({5, 7}));
  EXPECT_EQ(t.counts().given_up, 3);
  // A seq a window or more above the next: what lies below the window is never asked for.
  std::int64_t given_up = 0;
  EXPECT_EQ(seqs(t.offer(accepted(100), now, &given_up)), Seqs({9}));
  EXPECT_EQ(t.settled(MeasurementKind::kEdge, 1), 50);
  EXPECT_EQ(given_up, 42);  // 8, 10..50: at or below 100 − 50, stale at the intake
  EXPECT_EQ(seqs(t.releaseAll()), Seqs({100}));
  EXPECT_EQ(t.counts().held, 0);
  // Forget (an evicted sender): what it held, released; priors are their own stream.
  t.offer(accepted(1, 2), now);
  t.offer(accepted(3, 2), now);
  EXPECT_TRUE(t.giveUpTo(MeasurementKind::kPrior, 2, 10).empty());
  EXPECT_EQ(seqs(t.forget(MeasurementKind::kEdge, 2)), Seqs({3}));
  EXPECT_EQ(t.settled(MeasurementKind::kEdge, 2), 0);
}

TEST(GapTracker, RequestsCarryAtMost64RangesEachAValidResendMessage) {
  GapTracker t(milliseconds(1000), 1000, 100000);
  const auto now = Clock::now();
  for (std::int64_t s = 2; s <= 400; s += 2) t.offer(accepted(s), now);
  const std::vector<ResendRequest> q = t.requests();
  ASSERT_EQ(q.size(), 1u);
  ASSERT_EQ(q[0].missing.size(), static_cast<size_t>(kMaxResendRanges));
  EXPECT_EQ(q[0].missing.front().first, 1);
  EXPECT_EQ(q[0].missing.back().first, 127);
  ResendMessage m;
  m.sender = q[0].sender;
  m.settled = q[0].settled;
  m.highest = q[0].highest;
  m.missing = q[0].missing;
  const std::vector<std::uint8_t> b = encodeMessage(makeResendMessage(m));
  EXPECT_TRUE(decodeResend(b.data(), static_cast<int>(b.size())).ok());
  // A restart: what the journal held is settled, never asked for.
  GapTracker r(milliseconds(1000), 1000, 100000);
  r.restore(MeasurementKind::kEdge, 1, 400);
  EXPECT_EQ(seqs(r.offer(accepted(401), now)), Seqs({401}));
  EXPECT_EQ(r.requests().at(0).settled, 401);
}

// ---- ResendWindow ----

ResendMessage req(std::int64_t settled, std::int64_t highest,
                  std::vector<std::pair<std::int64_t, std::int64_t>> missing) {
  ResendMessage m;
  m.sender = 7;
  m.settled = settled;
  m.highest = highest;
  m.missing = std::move(missing);
  return m;
}

TEST(ResendWindow, ResendsWhatIsAskedOnceAnIntervalAnswersWhatIsGoneAndTheTail) {
  using cli::ResendWindow;
  ResendWindow w(5, 7);
  const auto t0 = Clock::now();
  for (std::int64_t s = 1; s <= 10; ++s)
    w.sent(false, s, "E", std::vector<std::uint8_t>(1, static_cast<std::uint8_t>(s)), t0);
  const auto later = t0 + milliseconds(1000);
  // Held: 6..10. 3..4 are gone (a WINDOW answer: settled 5), 7 is resent.
  ResendWindow::Answer a = w.request(req(2, 9, {{3, 4}, {7, 7}}), later);
  ASSERT_EQ(a.resend.size(), 1u);
  EXPECT_EQ(a.resend[0]->seq, 7);
  EXPECT_EQ(a.resend[0]->bytes, std::vector<std::uint8_t>(1, 7));
  EXPECT_EQ(a.unavailable, 2);
  ASSERT_TRUE(a.window.has_value());
  EXPECT_FALSE(a.window->request);
  EXPECT_EQ(a.window->settled, 5);
  EXPECT_EQ(a.window->highest, 10);
  // Asked again at once: not doubled. Another sender's request: nothing.
  EXPECT_TRUE(w.request(req(2, 9, {{7, 7}}), later + milliseconds(10)).resend.empty());
  ResendMessage other = req(2, 9, {{7, 7}});
  other.sender = 8;
  EXPECT_TRUE(w.request(other, later + milliseconds(500)).resend.empty());
  // The tail (10, above serve's highest 9) only once the stream is finished.
  EXPECT_TRUE(w.request(req(6, 9, {{7, 7}}), later + milliseconds(500)).resend.size() == 1);
  w.finished();
  a = w.request(req(9, 9, {}), later + milliseconds(1000));
  ASSERT_EQ(a.resend.size(), 1u);
  EXPECT_EQ(a.resend[0]->seq, 10);
  EXPECT_FALSE(w.acknowledged(false, 10));
  EXPECT_TRUE(w.acknowledged(true, 0));  // no priors sent
  EXPECT_EQ(w.tailProbes(later + milliseconds(2000)).size(), 1u);
  w.request(req(10, 10, {}), later + milliseconds(2000));
  EXPECT_TRUE(w.acknowledged(false, 10));
  EXPECT_TRUE(w.tailProbes(later + milliseconds(3000)).empty());
  EXPECT_EQ(w.counts().requests, 5);
}

// ---- the core ----

class RecordingPublisher final : public Publisher {
 public:
  void publishEstimate(const Estimate& e) override {
    std::lock_guard<std::mutex> lock(mutex_);
    last_seq_ = std::max(last_seq_, e.last_seq);
    cv_.notify_all();
  }
  void publishStatus(const CoreStatus&) override {}
  void publishCovariance(const CovarianceAnswer&) override {}
  void publishResend(const ResendRequest& r) override {
    std::lock_guard<std::mutex> lock(mutex_);
    requests_.push_back(r);
    cv_.notify_all();
  }
  bool waitCovered(std::int64_t seq) {
    std::unique_lock<std::mutex> lock(mutex_);
    return cv_.wait_for(lock, std::chrono::seconds(60), [&] { return last_seq_ >= seq; });
  }
  // The first request after `after` requests that asks for something.
  bool waitRequest(size_t after, ResendRequest* out) {
    std::unique_lock<std::mutex> lock(mutex_);
    return cv_.wait_for(lock, std::chrono::seconds(60), [&] {
      for (size_t k = after; k < requests_.size(); ++k) {
        if (!requests_[k].missing.empty()) {
          *out = requests_[k];
          return true;
        }
      }
      return false;
    });
  }
  std::vector<ResendRequest> requests() {
    std::lock_guard<std::mutex> lock(mutex_);
    return requests_;
  }

 private:
  std::mutex mutex_;
  std::condition_variable cv_;
  std::int64_t last_seq_ = 0;
  std::vector<ResendRequest> requests_;
};

Arrival arrivalOf(const StreamEdge<SE2>& e) {
  const std::vector<std::uint8_t> bytes = testing::edgeBytes(e);
  Arrival a;
  a.kind = MeasurementKind::kEdge;
  a.edge = e;
  a.fingerprint = EdgeIntake::fingerprint(bytes.data(), static_cast<int>(bytes.size()));
  return a;
}

std::vector<std::int64_t> journalSeqs(const std::vector<JournalEntry>& entries) {
  std::vector<std::int64_t> out;
  for (const JournalEntry& e : entries) {
    if (e.type == JournalEntry::Type::kMeasurement)
      out.push_back(std::get<StreamEdge<SE2>>(e.arrival.edge).seq);
  }
  return out;
}

TEST(LossRecoveryCore, EdgesAfterAGapWaitForItsResendAndAreAppliedInSeqOrderOnce) {
  const PoseGraph2 g = testing::manhattanGraph(60, 4, -1, 5);
  const std::vector<int> order = testing::replayOrder(g);
  const auto n = static_cast<std::int64_t>(order.size());
  const auto edge = [&](std::int64_t seq) {
    return testing::streamEdge(g, order[static_cast<size_t>(seq - 1)], seq);
  };
  StreamingOptions options;
  options.gap_hold = std::chrono::milliseconds(30000);
  options.resend_period = std::chrono::milliseconds(20);
  options.refine_on_exit = false;
  auto entries = std::make_shared<std::vector<JournalEntry>>();
  RecordingPublisher out;
  {
    StreamingCore core(out, std::make_unique<MemoryJournal>(entries), options);
    core.start();
    // Seqs 10 and 20..24 are lost on the way; the rest arrive.
    for (std::int64_t s = 1; s <= n; ++s) {
      if (s == 10 || (s >= 20 && s <= 24)) continue;
      core.receive(arrivalOf(edge(s)));
    }
    ASSERT_TRUE(out.waitCovered(9));
    EXPECT_EQ(core.status().loss.held, n - 10 - 5);  // 11..n but 20..24
    ResendRequest q;
    ASSERT_TRUE(out.waitRequest(0, &q));
    EXPECT_EQ(q.settled, 9);
    EXPECT_EQ(q.highest, n);
    ASSERT_EQ(q.missing.size(), 2u);
    EXPECT_EQ(q.missing[0], Range(10, 10));
    EXPECT_EQ(q.missing[1], Range(20, 24));
    // The resends, and a resent copy of one that had arrived (a duplicate, not a refusal).
    for (std::int64_t s : {10, 20, 21, 22, 23, 24, 11}) core.receive(arrivalOf(edge(s)));
    ASSERT_TRUE(out.waitCovered(n));
    core.stop();
    const ServeSummary& sum = core.summary();
    EXPECT_EQ(sum.applied, n);
    EXPECT_EQ(sum.intake.accepted, n);
    EXPECT_EQ(sum.intake.duplicates, 1);
    EXPECT_EQ(sum.intake.rejected, 0);
    EXPECT_EQ(sum.intake.gaps, 0);
    EXPECT_EQ(sum.loss.given_up, 0);
    EXPECT_EQ(sum.loss.held, 0);
  }
  // Journaled (and applied) in seq order, each once.
  std::vector<std::int64_t> expected;
  for (std::int64_t s = 1; s <= n; ++s) expected.push_back(s);
  EXPECT_EQ(journalSeqs(*entries), expected);

  // A restart on the journal asks for nothing it applied: the next edge settles at once.
  RecordingPublisher out2;
  StreamingCore again(out2, std::make_unique<MemoryJournal>(entries), options);
  again.start();
  StreamEdge<SE2> next = edge(n);  // to a new pose
  next.seq = n + 1;
  next.from = edge(n).to;
  next.to = 99999;
  again.receive(arrivalOf(next));
  ASSERT_TRUE(out2.waitCovered(n + 1));
  const auto deadline = Clock::now() + std::chrono::seconds(10);
  while (out2.requests().empty() && Clock::now() < deadline)
    std::this_thread::sleep_for(milliseconds(10));
  again.stop();
  const std::vector<ResendRequest> after = out2.requests();
  ASSERT_FALSE(after.empty());
  for (const ResendRequest& r : after) {
    EXPECT_TRUE(r.missing.empty());
    EXPECT_EQ(r.settled, n + 1);
  }
  EXPECT_EQ(again.summary().loss.held, 0);
}

// ---- the LCM service (memq://) ----

// Serve's requests as they appear on ARBOR_RESEND (dispatched by the service's receive thread,
// which handles the shared memq:// instance).
class RequestWatcher {
 public:
  RequestWatcher(lcm::LCM& lcm, const Channels& ch) : lcm_(lcm) {
    sub_ = lcm.subscribe(ch.resend, &RequestWatcher::onResend, this);
    sub_->setQueueCapacity(0);
  }
  ~RequestWatcher() { lcm_.unsubscribe(sub_); }
  bool waitMissing(std::int64_t first, std::int64_t last) {
    std::unique_lock<std::mutex> lock(mutex_);
    return cv_.wait_for(lock, std::chrono::seconds(60), [&] {
      for (const ResendMessage& m : seen_) {
        for (const auto& r : m.missing)
          if (r.first == first && r.second == last) return true;
      }
      return false;
    });
  }

 private:
  void onResend(const lcm::ReceiveBuffer* rbuf, const std::string&) {
    const ResendDecoding d = decodeResend(rbuf->data, static_cast<int>(rbuf->data_size));
    std::lock_guard<std::mutex> lock(mutex_);
    if (d.ok() && d.message.request) seen_.push_back(d.message);
    cv_.notify_all();
  }
  lcm::LCM& lcm_;
  lcm::Subscription* sub_ = nullptr;
  std::mutex mutex_;
  std::condition_variable cv_;
  std::vector<ResendMessage> seen_;
};

TEST(LossRecoveryService, RequestsGoOutOnArborResendAndAWindowAnswerGivesTheGapUp) {
  const PoseGraph2 g = testing::manhattanGraph(40, 4, -1, 3);
  const std::vector<int> order = testing::replayOrder(g);
  lcm::LCM lcm("memq://");
  ASSERT_TRUE(lcm.good());
  ServeOptions options;
  options.gap_hold = std::chrono::milliseconds(60000);
  options.resend_period = std::chrono::milliseconds(20);
  options.refine_on_exit = false;
  Service service(lcm, options);
  RequestWatcher watcher(lcm, service.channels());
  service.start();
  const auto send = [&](const std::string& channel, const std::vector<std::uint8_t>& b) {
    lcm.publish(channel, b.data(), static_cast<unsigned>(b.size()));
  };
  for (std::int64_t seq : {1, 2, 4, 5})
    send(service.channels().edges, testing::edgeBytes(g, order[static_cast<size_t>(seq - 1)], seq));
  ASSERT_TRUE(watcher.waitMissing(3, 3));
  const auto deadline = Clock::now() + std::chrono::seconds(60);
  while (service.status().loss_held != 2 && Clock::now() < deadline)
    std::this_thread::sleep_for(milliseconds(10));
  EXPECT_EQ(service.status().loss_held, 2);
  // Bad answers are refused by reason (a REQUEST where answers go, a range in a WINDOW).
  ResendMessage bad;
  bad.sender = 1;
  bad.settled = 3;
  bad.highest = 5;
  send(service.channels().resend_window, encodeMessage(makeResendMessage(bad)));
  resend_t ranged = makeResendMessage(bad);
  ranged.kind = resend_t::WINDOW;
  ranged.num_ranges = 1;
  ranged.first = {4};
  ranged.last = {4};
  send(service.channels().resend_window, encodeMessage(ranged));
  // The sender no longer holds seq 3: given up, 4 and 5 released in order.
  ResendMessage window;
  window.request = false;
  window.sender = 1;
  window.settled = 3;
  window.highest = 5;
  send(service.channels().resend_window, encodeMessage(makeResendMessage(window)));
  while (service.status().applied != 4 && Clock::now() < deadline)
    std::this_thread::sleep_for(milliseconds(10));
  const status_t st = service.status();
  EXPECT_EQ(st.applied, 4);
  EXPECT_EQ(st.loss_held, 0);
  EXPECT_EQ(st.loss_given_up, 1);
  EXPECT_EQ(st.loss_reordered, 2);
  EXPECT_GE(st.resend_requests, 1);
  EXPECT_EQ(st.control_refused, 2);
  service.stop();
  const ServeSummary& sum = service.summary();
  EXPECT_EQ(sum.control_refused.count("resend kind"), 1u);
  EXPECT_EQ(sum.control_refused.count("resend malformed"), 1u);
  EXPECT_EQ(sum.intake.gaps, 1);  // still counted: never received
}

}  // namespace
}  // namespace arbor::serve
