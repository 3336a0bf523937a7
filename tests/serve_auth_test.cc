// `arbor serve` with a deployment key, in process over memq:// (docs/lcm.md, "An authenticated
// bus"): a keyed stream is applied whole; unkeyed, wrong-key, tampered, replayed and
// wrong-channel messages — each a valid edge under a fresh seq that would otherwise be applied —
// are refused before decoding, counted by reason in status_t and the summary, and none of them
// is applied; the service's own estimates and status are sealed; rotation with a current and a
// next key. Every wait is on a condition, with a generous timeout only as a failure guard.
#include <condition_variable>
#include <cstdint>
#include <functional>
#include <mutex>
#include <string>
#include <vector>

#include <gtest/gtest.h>
#include <lcm/lcm-cpp.hpp>

#include "arbor_slam/io/lcm_messages.h"
#include "arbor_slam/tests/lcm_test_support.h"
#include "arbor_slam/tools/serve/bus_auth.h"
#include "arbor_slam/tools/serve/serve_service.h"

namespace arbor::serve {
namespace {

using testing::edgeBytes;
using testing::replayOrder;
using testing::streamEdge;

constexpr double kGuard = 60;  // seconds: a failure guard, never a pacing

BusKey keyOf(std::uint8_t fill) {
  std::array<std::uint8_t, 32> secret{};
  for (std::size_t i = 0; i < secret.size(); ++i) secret[i] = static_cast<std::uint8_t>(fill * i);
  return busKeyFromSecret(secret);
}

void publishSealed(lcm::LCM& lcm, BusAuth& auth, const std::string& channel,
                   const std::vector<std::uint8_t>& bytes) {
  const std::vector<std::uint8_t> sealed = auth.seal(channel, bytes.data(), bytes.size());
  lcm.publish(channel, sealed.data(), static_cast<unsigned>(sealed.size()));
}

void publishPlain(lcm::LCM& lcm, const std::string& channel,
                  const std::vector<std::uint8_t>& bytes) {
  lcm.publish(channel, bytes.data(), static_cast<unsigned>(bytes.size()));
}

// The service's estimates and status as a keyed client reads them; counts what arrives
// unsealed (none should).
class KeyedCollector {
 public:
  KeyedCollector(lcm::LCM& lcm, const Channels& ch, const BusKeyring& keys)
      : lcm_(lcm), auth_(keys) {
    subs_.push_back(lcm.subscribe(ch.estimate, &KeyedCollector::onEstimate, this));
    subs_.push_back(lcm.subscribe(ch.status, &KeyedCollector::onStatus, this));
    for (auto* s : subs_) s->setQueueCapacity(0);
  }
  ~KeyedCollector() {
    for (auto* s : subs_) lcm_.unsubscribe(s);
  }
  bool waitCovered(std::int64_t seq) {
    std::unique_lock<std::mutex> lock(mutex_);
    return cv_.wait_for(lock, std::chrono::duration<double>(kGuard),
                        [&] { return last_seq_ >= seq; });
  }
  bool waitStatus(const std::function<bool(const status_t&)>& pred) {
    std::unique_lock<std::mutex> lock(mutex_);
    return cv_.wait_for(lock, std::chrono::duration<double>(kGuard),
                        [&] { return have_status_ && pred(status_); });
  }
  int unverified() {
    std::lock_guard<std::mutex> lock(mutex_);
    return unverified_;
  }
  int plainDecodable() {
    std::lock_guard<std::mutex> lock(mutex_);
    return plain_decodable_;
  }

 private:
  template <class Msg>
  bool open(const lcm::ReceiveBuffer* rbuf, const std::string& channel, Msg* m) {
    const auto* data = static_cast<const std::uint8_t*>(rbuf->data);
    Msg plain;
    if (decodeMessage(data, static_cast<int>(rbuf->data_size), &plain) == MessageProblem::kNone) {
      std::lock_guard<std::mutex> lock(mutex_);
      ++plain_decodable_;
    }
    const OpenedMessage o = auth_.open(channel, data, rbuf->data_size);
    if (o.problem != AuthProblem::kNone) {
      std::lock_guard<std::mutex> lock(mutex_);
      ++unverified_;
      return false;
    }
    return decodeMessage(o.data, static_cast<int>(o.size), m) == MessageProblem::kNone;
  }
  void onEstimate(const lcm::ReceiveBuffer* rbuf, const std::string& channel) {
    estimate_t m;
    if (!open(rbuf, channel, &m)) return;
    std::lock_guard<std::mutex> lock(mutex_);
    last_seq_ = std::max(last_seq_, m.last_seq);
    cv_.notify_all();
  }
  void onStatus(const lcm::ReceiveBuffer* rbuf, const std::string& channel) {
    status_t s;
    if (!open(rbuf, channel, &s)) return;
    std::lock_guard<std::mutex> lock(mutex_);
    status_ = s;
    have_status_ = true;
    cv_.notify_all();
  }
  lcm::LCM& lcm_;
  BusAuth auth_;
  std::vector<lcm::Subscription*> subs_;
  std::mutex mutex_;
  std::condition_variable cv_;
  std::int64_t last_seq_ = 0;
  int unverified_ = 0, plain_decodable_ = 0;
  status_t status_;
  bool have_status_ = false;
};

std::int64_t reasonCount(const status_t& s, const std::string& reason) {
  for (int k = 0; k < s.num_reasons; ++k) {
    if (s.reason[k] == reason) return s.reason_count[k];
  }
  return 0;
}

class ServeAuth : public ::testing::Test {
 protected:
  ServeAuth() : graph_(testing::manhattanGraph(120, 4, -1, 3)), order_(replayOrder(graph_)) {}
  std::vector<std::uint8_t> edge(std::size_t k, std::int64_t seq, std::int64_t sender = 1) const {
    return edgeBytes(streamEdge(graph_, order_[k], seq, sender));
  }
  // A measurement of its own (the first edge's, moved 1 cm): applied as an extra factor.
  std::vector<std::uint8_t> extraEdge(std::int64_t seq, std::int64_t sender) const {
    StreamEdge<SE2> e = streamEdge(graph_, order_[0], seq, sender);
    e.z = e.z.compose(SE2(0.01, 0.0, 0.0));
    return edgeBytes(e);
  }
  PoseGraph2 graph_;
  std::vector<int> order_;
};

TEST_F(ServeAuth, OnlyVerifiedMessagesAreAppliedAndEveryRefusalIsCounted) {
  const BusKeyring keys = {keyOf(3)};
  lcm::LCM lcm("memq://");
  ServeOptions options;
  options.refine_on_exit = false;
  options.bus_keys = keys;
  Service service(lcm, options);
  KeyedCollector collector(lcm, service.channels(), keys);
  service.start();
  const Channels& ch = service.channels();
  BusAuth front_end(keys), intruder({keyOf(4)});
  const std::size_t half = order_.size() / 2;
  for (std::size_t k = 0; k < half; ++k) {
    publishSealed(lcm, front_end, ch.edges, edge(k, static_cast<std::int64_t>(k) + 1));
  }
  ASSERT_TRUE(collector.waitCovered(static_cast<std::int64_t>(half)));

  // Each hostile message carries the next real edge under a fresh seq, so it would be applied
  // if it got through. Two of each.
  for (int i = 0; i < 2; ++i) {
    const std::int64_t sender = 100 + i;  // seqs of their own: no clash with the real stream
    publishPlain(lcm, ch.edges, edge(half, 1, sender));             // unsigned
    publishSealed(lcm, intruder, ch.edges, edge(half, 2, sender));  // unknown key
    std::vector<std::uint8_t> bytes = edge(half, 3, sender);
    std::vector<std::uint8_t> tampered = front_end.seal(ch.edges, bytes.data(), bytes.size());
    tampered[kEnvelopeHeaderBytes + 40] ^= 0x01;  // one bit of the edge itself
    publishPlain(lcm, ch.edges, tampered);        // mac
    bytes = edge(half, 4, sender);
    publishPlain(lcm, ch.edges, front_end.seal(ch.priors, bytes.data(), bytes.size()));  // mac
  }
  // A replay: a keyed edge of a sender of its own, accepted once; two copies of its envelope.
  const std::vector<std::uint8_t> b = extraEdge(1, 200);
  const std::vector<std::uint8_t> recorded = front_end.seal(ch.edges, b.data(), b.size());
  for (int i = 0; i < 3; ++i) publishPlain(lcm, ch.edges, recorded);

  for (std::size_t k = half; k < order_.size(); ++k) {
    publishSealed(lcm, front_end, ch.edges, edge(k, static_cast<std::int64_t>(k) + 1));
  }
  ASSERT_TRUE(collector.waitCovered(static_cast<std::int64_t>(order_.size())));
  status_t s;
  ASSERT_TRUE(collector.waitStatus([&](const status_t& st) {
    s = st;
    return st.auth_refused == 10;
  })) << "status_t counts every refusal";
  EXPECT_EQ(reasonCount(s, "auth unsigned"), 2);
  EXPECT_EQ(reasonCount(s, "auth unknown key"), 2);
  EXPECT_EQ(reasonCount(s, "auth mac"), 4);
  EXPECT_EQ(reasonCount(s, "auth replay"), 2);
  service.stop();
  const ServeSummary& summary = service.summary();
  // Decoded and applied: the real stream and sender 200's one keyed edge, never a refused one.
  EXPECT_EQ(summary.intake.received, static_cast<std::int64_t>(order_.size()) + 1);
  EXPECT_EQ(summary.auth_refused.at("unsigned"), 2);
  EXPECT_EQ(summary.auth_refused.at("unknown key"), 2);
  EXPECT_EQ(summary.auth_refused.at("mac"), 4);
  EXPECT_EQ(summary.auth_refused.at("replay"), 2);
  EXPECT_EQ(summary.auth_refused.count("clock"), 0u);
  EXPECT_EQ(summary.intake.accepted, static_cast<std::int64_t>(order_.size()) + 1);
  EXPECT_EQ(summary.applied, static_cast<std::int64_t>(order_.size()) + 1);
  EXPECT_EQ(summary.intake.gaps, 0);
  // What the service published was sealed: nothing decoded as a plain message, all verified.
  EXPECT_EQ(collector.unverified(), 0);
  EXPECT_EQ(collector.plainDecodable(), 0);
}

TEST_F(ServeAuth, RotationAcceptsTheCurrentAndTheNextKeyAndRefusesARetiredOne) {
  const BusKey current = keyOf(5), next = keyOf(6);
  lcm::LCM lcm("memq://");
  ServeOptions options;
  options.refine_on_exit = false;
  options.bus_keys = {next, current};  // the service re-keyed first: signs with next
  Service service(lcm, options);
  KeyedCollector old_client(lcm, service.channels(), {current, next});
  service.start();
  const Channels& ch = service.channels();
  BusAuth not_yet_rekeyed({current}), rekeyed({next, current}), retired({keyOf(7)});
  const std::size_t n = order_.size();
  for (std::size_t k = 0; k < n; ++k) {
    BusAuth& by = k % 2 == 0 ? not_yet_rekeyed : rekeyed;  // both kinds of node, interleaved
    publishSealed(lcm, by, ch.edges, edge(k, static_cast<std::int64_t>(k) + 1));
    if (k == n / 2) publishSealed(lcm, retired, ch.edges, edge(k, 1, 300));
  }
  ASSERT_TRUE(old_client.waitCovered(static_cast<std::int64_t>(n)));
  // The last step, without a restart (SIGHUP in `arbor serve`): the current key is retired.
  service.setBusKeys({next});
  publishSealed(lcm, not_yet_rekeyed, ch.edges, edge(0, 1, 301));
  publishSealed(lcm, rekeyed, ch.edges, extraEdge(static_cast<std::int64_t>(n) + 1, 1));
  ASSERT_TRUE(old_client.waitCovered(static_cast<std::int64_t>(n) + 1));
  service.stop();
  EXPECT_EQ(service.summary().applied, static_cast<std::int64_t>(n) + 1);
  EXPECT_EQ(service.summary().auth_refused.at("unknown key"), 2);
  EXPECT_EQ(old_client.unverified(), 0);
}

// Issue 56: with a key the receive link's probe travels sealed as well: every probe on the bus
// opens with the deployment key, none is plain, and the link comes up on its sealed probe.
TEST_F(ServeAuth, TheLinksProbeIsSealedAndTheLinkComesUpOnIt) {
  const BusKeyring keys = {keyOf(5)};
  lcm::LCM lcm("memq://");
  ServeOptions options;
  options.refine_on_exit = false;
  options.bus_keys = keys;
  Service service(lcm, options);
  KeyedCollector collector(lcm, service.channels(), keys);
  BusAuth observer(keys);
  std::mutex mutex;
  int probes = 0, sealed = 0;
  struct ProbeSpy {
    std::function<void(const lcm::ReceiveBuffer*, const std::string&)> f;
    void on(const lcm::ReceiveBuffer* rbuf, const std::string& channel) { f(rbuf, channel); }
  } spy;
  spy.f = [&](const lcm::ReceiveBuffer* rbuf, const std::string& channel) {
    const OpenedMessage o =
        observer.open(channel, static_cast<const std::uint8_t*>(rbuf->data), rbuf->data_size);
    std::lock_guard<std::mutex> lock(mutex);
    ++probes;
    if (o.problem == AuthProblem::kNone && o.size > 0) ++sealed;
  };
  lcm::Subscription* sub = lcm.subscribe(service.channels().link_probe, &ProbeSpy::on, &spy);
  service.start();
  BusAuth front_end(keys);
  publishSealed(lcm, front_end, service.channels().edges, edge(0, 1));
  ASSERT_TRUE(collector.waitStatus([](const status_t& s) { return s.receive_link_up; }));
  service.stop();
  lcm.unsubscribe(sub);
  std::lock_guard<std::mutex> lock(mutex);
  EXPECT_GE(probes, 1);
  EXPECT_EQ(sealed, probes);
  EXPECT_EQ(collector.unverified(), 0);
}

TEST_F(ServeAuth, WithoutAKeyNothingChanges) {
  lcm::LCM lcm("memq://");
  ServeOptions options;
  options.refine_on_exit = false;
  Service service(lcm, options);
  testing::Collector collector(lcm, service.channels());  // decodes plain messages
  service.start();
  for (std::size_t k = 0; k < order_.size(); ++k) {
    publishPlain(lcm, service.channels().edges, edge(k, static_cast<std::int64_t>(k) + 1));
  }
  ASSERT_TRUE(collector.waitCovered(static_cast<std::int64_t>(order_.size()), kGuard));
  service.stop();
  EXPECT_EQ(service.summary().applied, static_cast<std::int64_t>(order_.size()));
  EXPECT_TRUE(service.summary().auth_refused.empty());
}

}  // namespace
}  // namespace arbor::serve
