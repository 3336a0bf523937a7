// A command's answer on the bus: listens on one channel (its own handle thread on the LCM
// instance it is given) for messages of type Msg, and keeps the first one `matches` accepts.
// waitAny() waits for any well-formed message (the service is up and subscribed at the hub),
// waitAnswer() for the match. Messages that do not decode are ignored, and with a key
// (tools/cli/bus_key_flag.h) so are those whose envelope does not verify.
#pragma once

#include <chrono>
#include <condition_variable>
#include <functional>
#include <mutex>
#include <string>
#include <thread>
#include <utility>

#include <lcm/lcm-cpp.hpp>

#include "arbor_slam/io/lcm_messages.h"
#include "arbor_slam/tools/cli/bus_key_flag.h"
#include "arbor_slam/tools/serve/lcm_tuning.h"

namespace arbor::cli {

template <class Msg>
class AnswerWatcher {
 public:
  AnswerWatcher(lcm::LCM& lcm, const std::string& channel, std::function<bool(const Msg&)> matches,
                serve::BusAuth* auth = nullptr)
      : lcm_(lcm), matches_(std::move(matches)), auth_(auth) {
    sub_ = lcm_.subscribe(channel, &AnswerWatcher::onMessage, this);
    sub_->setQueueCapacity(0);
    thread_ = std::thread([this] {
      while (!stop_) {
        serve::armQuickAck(lcm_);
        lcm_.handleTimeout(20);
      }
    });
  }
  ~AnswerWatcher() {
    stop_ = true;
    thread_.join();
    lcm_.unsubscribe(sub_);
  }
  AnswerWatcher(const AnswerWatcher&) = delete;
  AnswerWatcher& operator=(const AnswerWatcher&) = delete;

  bool waitAny(double timeout_s) {
    std::unique_lock<std::mutex> lock(mutex_);
    return cv_.wait_for(lock, std::chrono::duration<double>(timeout_s), [&] { return seen_; });
  }
  bool waitAnswer(double timeout_s, Msg* out) {
    std::unique_lock<std::mutex> lock(mutex_);
    const bool done =
        cv_.wait_for(lock, std::chrono::duration<double>(timeout_s), [&] { return answered_; });
    if (done) *out = answer_;
    return done;
  }

 private:
  void onMessage(const lcm::ReceiveBuffer* rbuf, const std::string& channel) {
    const std::uint8_t* data = nullptr;
    int size = 0;
    if (!openFromBus(auth_, channel, rbuf, &data, &size)) return;
    Msg m;
    if (decodeMessage(data, size, &m) != MessageProblem::kNone) return;
    std::lock_guard<std::mutex> lock(mutex_);
    seen_ = true;
    if (!answered_ && matches_(m)) {
      answered_ = true;
      answer_ = m;
    }
    cv_.notify_all();
  }

  lcm::LCM& lcm_;
  std::function<bool(const Msg&)> matches_;
  serve::BusAuth* auth_;  // with a key (else null)
  lcm::Subscription* sub_ = nullptr;
  std::mutex mutex_;
  std::condition_variable cv_;
  bool seen_ = false, answered_ = false;
  Msg answer_;
  volatile bool stop_ = false;
  std::thread thread_;
};

}  // namespace arbor::cli
