// One LCM instance that may fail under the service: the link to the transport. liblcm 1.3
// aborts the process (FD_SET on socket −1 inside lcm_handle_timeout) when a tcpq:// instance has
// lost its hub or never reached it; lcm_create itself returns an instance (not NULL) when the
// hub is absent. LinkWatch never calls lcm_handle_timeout: it polls the instance's descriptor
// itself and calls lcm_handle only when there is something to read, so a dead link is seen as a
// descriptor < 0 or a failed handle, never an abort.
//
// A dead link is re-created (destroyed, lcm_create again, every subscription made again) with
// exponential backoff, `backoff_min_ms` doubling up to `backoff_max_ms`; a link that fails again
// within backoff_max_ms of coming up keeps its grown backoff, so a flapping transport costs at
// most one attempt, and one down/up pair of log lines, per backoff_max_ms. After each creation the
// receiving link publishes a probe on its own instance; the probe coming back proves the
// transport holds every subscription (the Java hub handles one client's messages in order), and
// only then is the link reported up. A probe unanswered for backoff_max_ms is sent again (the
// hub may relay a new client's first message before it lists that client as a receiver); after
// three unanswered probes a tcpq:// link is treated as dead and re-created (other providers
// only send it again). Each state change is
// logged, one line (down, with why; up, with how long it was down).
//
// Over tcpq:// every creation is preceded by a bounded check of the hub's handshake
// (tools/serve/tcpq_handshake.h; liblcm's own blocks without a timeout): a hub that accepts the
// connection and never answers leaves the link down, logged, and retried like an absent one. The
// check runs on a thread of its own after the first (at construction it runs inline), so neither
// the receive nor the publishing thread waits for it.
//
// A borrowed instance (memq:// shared in-process) is watched the same way but never re-created.
// Not thread-safe: one thread handles; publish() is safe against other publish() calls only.
#pragma once

#include <atomic>
#include <chrono>
#include <cstdint>
#include <functional>
#include <future>
#include <memory>
#include <mutex>
#include <string>
#include <vector>

#include <lcm/lcm-cpp.hpp>

namespace arbor::serve {

struct LinkWatchOptions {
  std::string url;            ///< LCM provider URL ("" = LCM_DEFAULT_URL / LCM's default)
  std::string name = "link";  ///< in log lines ("receive link", "publish link")
  int backoff_min_ms = 50;    ///< first retry after this long, doubling ...
  int backoff_max_ms = 2000;  ///< ... up to this
  /// Channel of the probe that confirms the subscriptions after each creation ("" = no probe:
  /// the link is up as soon as it has a descriptor). Only a receiving link needs one.
  std::string probe_channel;
  std::function<void(const std::string&)> log;  ///< state changes; nullptr: silent
  /// tcpq://: how long the hub may take to answer the handshake check before each creation.
  int handshake_timeout_ms = 2000;
  /// Only publish(): the instance is never asked for its descriptor, never subscribed or
  /// handled. For udpm://, whose liblcm instance starts its receive thread (and its fragment
  /// reassembly) on the first of those: a sending instance then parses no datagram. Up once
  /// created; a failed publish re-creates it. subscribe() and handle() throw std::logic_error.
  bool publish_only = false;
};

struct LinkCounts {
  std::int64_t outages = 0;           ///< times the link went down
  std::int64_t creations = 0;         ///< instances created successfully (the first included)
  std::int64_t failed_publishes = 0;  ///< messages not sent because the link was down
};

class LinkWatch {
 public:
  using Handler = std::function<void(const lcm::ReceiveBuffer*, const std::string&)>;

  /// Creates the instance now. Throws std::runtime_error when lcm_create refuses the URL (a
  /// provider or address that cannot work); an instance without a connection (tcpq:// with no
  /// hub yet) is a link that is down and retried.
  explicit LinkWatch(LinkWatchOptions options);
  /// Watches `borrowed` (which must outlive this); never re-created.
  LinkWatch(lcm::LCM& borrowed, LinkWatchOptions options);
  ~LinkWatch();
  LinkWatch(const LinkWatch&) = delete;
  LinkWatch& operator=(const LinkWatch&) = delete;

  /// Subscribes now (if the link is up) and after every re-creation; queue capacity 0 (liblcm
  /// drops nothing; the caller's own queue is the only one).
  void subscribe(const std::string& channel, Handler handler);
  /// Drops every subscription.
  void unsubscribeAll();
  /// The channels subscribed by subscribe(), in that order (the probe's own is not among them).
  std::vector<std::string> channels() const {
    std::vector<std::string> out;
    for (const auto& s : subscriptions_) out.push_back(s->channel);
    return out;
  }
  /// Waits up to `timeout_ms` for a message and dispatches it. 1: one handled; 0: none arrived;
  /// −1: the link is down (re-created here when the backoff allows; else waits out the timeout).
  int handle(int timeout_ms);
  /// Publishes when the link is up (re-creating it first when it is down and the backoff
  /// allows); false when it could not be sent (counted).
  bool publish(const std::string& channel, const void* data, unsigned size);
  /// With a deployment key: the probe travels sealed (seal: its bytes in the bus's envelope),
  /// and a probe that comes back counts only when open gives its token back (false: refused).
  /// Set before the first handle().
  using ProbeSeal = std::function<std::vector<std::uint8_t>(const std::string& channel,
                                                            const std::string& token)>;
  using ProbeOpen = std::function<bool(const std::string& channel, const std::uint8_t* data,
                                       std::size_t size, std::string* token)>;
  void sealProbes(ProbeSeal seal, ProbeOpen open) {
    probe_seal_ = std::move(seal);
    probe_open_ = std::move(open);
  }
  /// Up and, with a probe, confirmed.
  bool up() const { return up_; }
  /// True once after each time the link came up again after an outage (a publisher's cue to
  /// send full state, since what it sent meanwhile is lost).
  bool takeRecovered() { return recovered_.exchange(false); }
  LinkCounts counts() const;
  const std::string& url() const { return options_.url; }

 private:
  struct Subscription {
    std::string channel;
    Handler handler;
  };
  static void dispatch(const lcm::ReceiveBuffer* rbuf, const std::string& channel, Subscription* s);
  void onProbe(const lcm::ReceiveBuffer* rbuf, const std::string& channel);
  lcm::LCM* instance() const { return owned_ ? owned_.get() : borrowed_; }
  /// Creates (owned) and subscribes; true if the instance has a descriptor.
  bool create();
  void subscribeOn(lcm::LCM& lcm, Subscription& s);
  void sendProbe();
  void markDown(const std::string& why);
  void markUp();
  void markConnected();
  /// Re-creates when due; true if the link has a descriptor afterwards.
  bool retryIfDue();
  void log(const std::string& line);

  LinkWatchOptions options_;
  lcm::LCM* borrowed_ = nullptr;
  std::unique_ptr<lcm::LCM> owned_;
  std::vector<std::unique_ptr<Subscription>> subscriptions_;
  std::vector<lcm::Subscription*> lcm_subscriptions_;  ///< on the current instance
  lcm::Subscription* probe_subscription_ = nullptr;
  std::string probe_token_;
  ProbeSeal probe_seal_;
  ProbeOpen probe_open_;
  std::int64_t probes_sent_ = 0;
  static constexpr int kMaxUnansweredProbes = 3;
  int probes_unanswered_ = 0;  ///< since the last connection
  std::chrono::steady_clock::time_point probe_sent_at_;

  enum class State { kNew, kDown, kProbing, kUp };
  State state_ = State::kNew;  ///< kProbing: connected, the probe not back yet
  bool connected() const { return state_ == State::kProbing || state_ == State::kUp; }
  bool probe_pending_ = false;  ///< a probe is to be sent by the next handle()
  std::atomic<bool> up_{false};
  std::atomic<bool> recovered_{false};
  std::chrono::steady_clock::time_point down_since_, next_attempt_, up_since_;
  int backoff_ms_ = 0;
  std::int64_t attempts_ = 0;  ///< since the link went down
  std::string down_reason_;

  bool tcpq_ = false;                   ///< owned tcpq:// link: check the hub before creating
  std::future<std::string> hub_check_;  ///< a handshake check in flight (tcpq)
  std::string last_check_problem_;      ///< the last check's answer, logged when it changes

  mutable std::mutex counts_mutex_;
  LinkCounts counts_;
};

}  // namespace arbor::serve
