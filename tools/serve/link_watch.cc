#include "arbor_slam/tools/serve/link_watch.h"

#include <algorithm>
#include <cerrno>
#include <cstring>
#include <stdexcept>
#include <thread>

#include <poll.h>
#include <unistd.h>

#include "arbor_slam/core/elapsed.h"
#include "arbor_slam/tools/serve/lcm_tuning.h"
#include "arbor_slam/tools/serve/tcpq_handshake.h"

namespace arbor::serve {
namespace {

using Clock = std::chrono::steady_clock;

std::string describe(const std::string& url) { return url.empty() ? "LCM's default URL" : url; }

}  // namespace

LinkWatch::LinkWatch(LinkWatchOptions options) : options_(std::move(options)) {
  if (options_.backoff_min_ms < 1 || options_.backoff_max_ms < options_.backoff_min_ms) {
    throw std::invalid_argument("LinkWatch: backoff " + std::to_string(options_.backoff_min_ms) +
                                " .. " + std::to_string(options_.backoff_max_ms) +
                                " ms is not 1 <= min <= max");
  }
  std::string host;
  int port = 0;
  tcpq_ = tcpqHostPort(options_.url, &host, &port);  // else lcm_create judges the URL
  if (tcpq_) {
    last_check_problem_ = tcpqHandshakeProblem(options_.url, options_.handshake_timeout_ms);
    if (!last_check_problem_.empty()) {
      markDown("cannot connect to " + describe(options_.url) + ": " + last_check_problem_);
      return;
    }
  }
  owned_ = std::make_unique<lcm::LCM>(options_.url);
  if (!owned_->good()) {
    throw std::runtime_error("cannot open LCM at '" + describe(options_.url) +
                             "' (liblcm refused the URL)");
  }
  ++counts_.creations;
  if (options_.publish_only) {
    markConnected();
  } else if (owned_->getFileno() < 0) {
    markDown("cannot connect to " + describe(options_.url));
  } else {
    tuneLcmTransport(*owned_, options_.url);
    markConnected();
  }
}

LinkWatch::LinkWatch(lcm::LCM& borrowed, LinkWatchOptions options)
    : options_(std::move(options)), borrowed_(&borrowed) {
  if (borrowed.good() && borrowed.getFileno() >= 0) {
    markConnected();
  } else {
    markDown("the instance has no connection");
  }
}

void LinkWatch::markConnected() {
  probes_unanswered_ = 0;
  if (options_.probe_channel.empty()) {
    markUp();
  } else {
    state_ = State::kProbing;
    probe_pending_ = true;  // sent by handle(), after every subscription
  }
}

LinkWatch::~LinkWatch() { unsubscribeAll(); }

void LinkWatch::log(const std::string& line) {
  if (options_.log) options_.log(options_.name + " " + line);
}

LinkCounts LinkWatch::counts() const {
  std::lock_guard<std::mutex> lock(counts_mutex_);
  return counts_;
}

void LinkWatch::dispatch(const lcm::ReceiveBuffer* rbuf, const std::string& channel,
                         Subscription* s) {
  s->handler(rbuf, channel);
}

void LinkWatch::subscribeOn(lcm::LCM& lcm, Subscription& s) {
  lcm::Subscription* sub = lcm.subscribeFunction(s.channel, &LinkWatch::dispatch, &s);
  if (sub == nullptr) return;
  sub->setQueueCapacity(0);
  lcm_subscriptions_.push_back(sub);
}

void LinkWatch::subscribe(const std::string& channel, Handler handler) {
  if (options_.publish_only) throw std::logic_error("LinkWatch: subscribe on a publish-only link");
  subscriptions_.push_back(
      std::make_unique<Subscription>(Subscription{channel, std::move(handler)}));
  if (lcm::LCM* lcm = instance(); lcm != nullptr && lcm->good()) {
    subscribeOn(*lcm, *subscriptions_.back());
  }
}

void LinkWatch::unsubscribeAll() {
  lcm::LCM* lcm = instance();
  if (lcm != nullptr && lcm->good()) {
    for (lcm::Subscription* s : lcm_subscriptions_) lcm->unsubscribe(s);
    if (probe_subscription_ != nullptr) lcm->unsubscribe(probe_subscription_);
  }
  lcm_subscriptions_.clear();
  probe_subscription_ = nullptr;
  subscriptions_.clear();
}

void LinkWatch::sendProbe() {
  lcm::LCM* lcm = instance();
  if (lcm == nullptr || !lcm->good()) return;
  if (probe_subscription_ == nullptr) {
    probe_subscription_ = lcm->subscribe(options_.probe_channel, &LinkWatch::onProbe, this);
  }
  probe_token_ = std::to_string(::getpid()) + ":" + std::to_string(++probes_sent_) + ":" +
                 std::to_string(reinterpret_cast<std::uintptr_t>(this));
  probe_sent_at_ = Clock::now();
  probe_pending_ = false;
  ++probes_unanswered_;
  int sent = 0;
  if (probe_seal_) {
    const std::vector<std::uint8_t> sealed = probe_seal_(options_.probe_channel, probe_token_);
    sent =
        lcm->publish(options_.probe_channel, sealed.data(), static_cast<unsigned>(sealed.size()));
  } else {
    sent = lcm->publish(options_.probe_channel, probe_token_.data(),
                        static_cast<unsigned>(probe_token_.size()));
  }
  if (sent != 0) {
    markDown("probe could not be sent");
  }
}

void LinkWatch::onProbe(const lcm::ReceiveBuffer* rbuf, const std::string& channel) {
  std::string token;
  if (probe_open_) {
    if (!probe_open_(channel, static_cast<const std::uint8_t*>(rbuf->data), rbuf->data_size,
                     &token))
      return;  // not our sealed probe
  } else {
    token.assign(static_cast<const char*>(rbuf->data), rbuf->data_size);
  }
  if (state_ == State::kProbing && token == probe_token_) {
    probes_unanswered_ = 0;
    markUp();
  }
}

void LinkWatch::markDown(const std::string& why) {
  if (state_ == State::kDown) return;
  // Up for less than the longest backoff: a flapping transport, whose backoff keeps growing
  // (so its down/up lines come at most once per backoff_max_ms); else it starts again.
  const bool flapping =
      state_ != State::kNew && backoff_ms_ > 0 &&
      Clock::now() - up_since_ < std::chrono::milliseconds(options_.backoff_max_ms);
  state_ = State::kDown;
  up_ = false;
  {
    std::lock_guard<std::mutex> lock(counts_mutex_);
    ++counts_.outages;
  }
  down_since_ = Clock::now();
  backoff_ms_ =
      flapping ? std::min(2 * backoff_ms_, options_.backoff_max_ms) : options_.backoff_min_ms;
  next_attempt_ = down_since_ + std::chrono::milliseconds(backoff_ms_);
  attempts_ = 0;
  down_reason_ = why;
  log(std::string("down: ") + why +
      (borrowed_ ? "; waiting for it"
                 : "; re-creating it with backoff " + std::to_string(options_.backoff_min_ms) +
                       " ms to " + std::to_string(options_.backoff_max_ms) + " ms"));
}

void LinkWatch::markUp() {
  if (state_ == State::kUp) return;
  state_ = State::kUp;
  up_ = true;
  up_since_ = Clock::now();
  if (counts().outages > 0) {
    recovered_ = true;
    log("up again after " +
        std::to_string(static_cast<long long>(secondsSince(down_since_) * 1000)) + " ms down (" +
        std::to_string(attempts_) + " re-creations)");
  } else {
    log("up on " + describe(options_.url));
  }
  attempts_ = 0;
}

bool LinkWatch::create() {
  lcm_subscriptions_.clear();  // deleted with the old instance
  probe_subscription_ = nullptr;
  owned_.reset();  // closes the dead socket
  if (tcpq_) {
    // The hub must answer a handshake first: liblcm's own would block forever on a silent one.
    if (!hub_check_.valid()) {
      hub_check_ = std::async(std::launch::async, tcpqHandshakeProblem, options_.url,
                              options_.handshake_timeout_ms);
      return false;
    }
    if (hub_check_.wait_for(std::chrono::seconds(0)) != std::future_status::ready) return false;
    const std::string problem = hub_check_.get();
    if (!problem.empty()) {
      if (problem != last_check_problem_) log("still down: " + problem);
      last_check_problem_ = problem;
      return false;
    }
    last_check_problem_.clear();
  }
  owned_ = std::make_unique<lcm::LCM>(options_.url);
  if (!owned_->good()) return false;
  {
    std::lock_guard<std::mutex> lock(counts_mutex_);
    ++counts_.creations;
  }
  if (options_.publish_only) {
    markConnected();
    return true;
  }
  if (owned_->getFileno() < 0) return false;
  tuneLcmTransport(*owned_, options_.url);
  for (auto& s : subscriptions_) subscribeOn(*owned_, *s);
  if (owned_->getFileno() < 0) return false;  // lost while subscribing
  markConnected();
  return true;
}

bool LinkWatch::retryIfDue() {
  if (connected()) return true;
  const auto now = Clock::now();
  if (now < next_attempt_) return false;
  ++attempts_;
  if (borrowed_ != nullptr) {
    if (borrowed_->good() && borrowed_->getFileno() >= 0) markConnected();
  } else {
    create();
  }
  if (connected()) return true;
  backoff_ms_ = std::min(2 * backoff_ms_, options_.backoff_max_ms);
  next_attempt_ = Clock::now() + std::chrono::milliseconds(backoff_ms_);
  return false;
}

int LinkWatch::handle(int timeout_ms) {
  if (options_.publish_only) throw std::logic_error("LinkWatch: handle on a publish-only link");
  const auto start = Clock::now();
  lcm::LCM* lcm = instance();
  int fd = lcm != nullptr && lcm->good() ? lcm->getFileno() : -1;
  if (fd < 0 || state_ == State::kDown) {
    markDown("the connection closed");
    if (!retryIfDue()) {
      const auto until = std::min(next_attempt_, start + std::chrono::milliseconds(timeout_ms));
      std::this_thread::sleep_until(until);
      return -1;
    }
    lcm = instance();
    fd = lcm->getFileno();
    if (fd < 0) return -1;
  }
  if (state_ == State::kProbing &&
      (probe_pending_ ||
       Clock::now() - probe_sent_at_ >= std::chrono::milliseconds(options_.backoff_max_ms))) {
    // Again after a while: the Java hub can relay a client's first message before it lists
    // that client as a receiver, and a datagram transport may drop it. A link whose probes do
    // not come back is not trusted: it is made anew.
    // Only over tcpq, whose hub can hold a connection that relays nothing: a datagram
    // transport is never torn down for a lost probe (what it receives meanwhile would be lost).
    if (probes_unanswered_ >= kMaxUnansweredProbes && options_.url.rfind("tcpq://", 0) == 0) {
      markDown("its probe did not come back " + std::to_string(probes_unanswered_) + " times");
      return -1;
    }
    sendProbe();
    if (!connected()) return -1;
  }
  armQuickAck(*lcm);
  pollfd p{fd, POLLIN, 0};
  const int r = ::poll(&p, 1, std::max(0, timeout_ms));
  if (r < 0) {
    if (errno == EINTR) return 0;
    markDown(std::string("poll failed: ") + std::strerror(errno));
    return -1;
  }
  if (r == 0) return 0;
  if (lcm->handle() != 0) {
    markDown("receive failed (transport gone)");
    return -1;
  }
  return 1;
}

bool LinkWatch::publish(const std::string& channel, const void* data, unsigned size) {
  lcm::LCM* lcm = instance();
  if (!connected() || lcm == nullptr || !lcm->good() ||
      (!options_.publish_only && lcm->getFileno() < 0)) {
    markDown("the connection closed");
    if (!retryIfDue()) {
      std::lock_guard<std::mutex> lock(counts_mutex_);
      ++counts_.failed_publishes;
      return false;
    }
    lcm = instance();
  }
  if (lcm->publish(channel, data, size) != 0) {
    markDown("publish failed (transport gone)");
    std::lock_guard<std::mutex> lock(counts_mutex_);
    ++counts_.failed_publishes;
    return false;
  }
  return true;
}

}  // namespace arbor::serve
