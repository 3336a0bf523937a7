#include "arbor_slam/tools/serve/serve_service.h"

#include <algorithm>
#include <stdexcept>

#include "arbor_slam/tools/serve/lcm_event_journal.h"
#include "arbor_slam/tools/serve/lcm_mapping.h"
#include "arbor_slam/tools/serve/lcm_tuning.h"

namespace arbor::serve {

LcmService::LcmService(lcm::LCM& lcm, ServeOptions options)
    : LcmService(lcm, lcm, std::move(options)) {}

LcmService::LcmService(lcm::LCM& receive, lcm::LCM& publish, ServeOptions options)
    : LcmService(nullptr, nullptr, std::move(options), nullptr) {
  LinkWatchOptions r;
  r.name = "receive link";
  r.probe_channel = channels_.link_probe;
  r.log = [this](const std::string& line) { core_->logLine(line); };
  LinkWatchOptions p = r;
  p.name = "publish link";
  p.probe_channel.clear();
  owned_receive_ = std::make_unique<LinkWatch>(receive, r);
  owned_publish_ = std::make_unique<LinkWatch>(publish, p);
  receive_ = owned_receive_.get();
  publish_ = owned_publish_.get();
  sealProbes();
}

LcmService::LcmService(LinkWatch& receive, LinkWatch& publish, ServeOptions options,
                       UdpmReceiver* datagrams)
    : LcmService(&receive, &publish, std::move(options), datagrams) {}

LcmService::LcmService(LinkWatch* receive, LinkWatch* publish, ServeOptions options,
                       UdpmReceiver* datagrams)
    : receive_(receive),
      publish_(publish),
      datagrams_(datagrams),
      options_(std::move(options)),
      channels_(Channels::withPrefix(options_.channel_prefix)) {
  std::unique_ptr<JournalSink> journal;
  if (!options_.journal_path.empty()) {
    journal = std::make_unique<LcmEventJournal>(
        options_.journal_path, channels_,
        EventLogWriterOptions{options_.fsync_interval_ms, options_.journal_max_bytes,
                              options_.journal_reserve_bytes});
  }
  core_ = std::make_unique<StreamingCore>(*this, std::move(journal),
                                          static_cast<const StreamingOptions&>(options_));
  if (!options_.bus_keys.empty()) auth_ = std::make_unique<BusAuth>(options_.bus_keys);
  sealProbes();
}

void LcmService::sealProbes() {
  // With a key every message this service sends is sealed, its receive link's probe too.
  if (!auth_ || receive_ == nullptr) return;
  receive_->sealProbes(
      [this](const std::string& channel, const std::string& token) {
        return auth_->seal(channel, reinterpret_cast<const std::uint8_t*>(token.data()),
                           token.size());
      },
      [this](const std::string& channel, const std::uint8_t* data, std::size_t size,
             std::string* token) {
        const OpenedMessage opened = auth_->open(channel, data, size);
        if (opened.problem != AuthProblem::kNone) return false;
        token->assign(reinterpret_cast<const char*>(opened.data), opened.size);
        return true;
      });
}

LcmService::~LcmService() {
  if (running_) {
    try {
      stop();
    } catch (...) {
    }
  }
  if (auth_ && receive_ != nullptr) receive_->sealProbes(nullptr, nullptr);  // they name auth_
}

void LcmService::start() {
  if (running_) throw std::logic_error("serve: start() twice");
  core_->start();
  // Queue capacity 0 at liblcm (LinkWatch): never dropped there, the queue is the core's.
  const auto on = [this](MeasurementKind kind, int limit) {
    return [this, kind, limit](const lcm::ReceiveBuffer* rbuf, const std::string& channel) {
      onMeasurement(rbuf, channel, kind, limit);
    };
  };
  const MessageLimits& limits = options_.message_limits;
  receive_->subscribe(channels_.edges, on(MeasurementKind::kEdge, limits.edge));
  receive_->subscribe(channels_.priors, on(MeasurementKind::kPrior, limits.prior));
  receive_->subscribe(channels_.command,
                      [this](const lcm::ReceiveBuffer* rbuf, const std::string& channel) {
                        onCommand(rbuf, channel);
                      });
  receive_->subscribe(channels_.edge_commands, on(MeasurementKind::kCommand, limits.edge_command));
  receive_->subscribe(channels_.resend_window,
                      [this](const lcm::ReceiveBuffer* rbuf, const std::string& channel) {
                        onResendWindow(rbuf, channel);
                      });
  if (options_.udpm_port > 0) {  // the socket exists from the first subscribe on
    const std::int64_t bytes = udpReceiveBufferBytes(options_.udpm_port);
    recv_buf_at_start_ = bytes;
    core_->logLine("udpm receive buffer " + std::to_string(bytes) + " bytes (SO_RCVBUF)");
  }
  if (auth_) {
    core_->logLine("authenticated bus: signing with key " + busKeyIdText(auth_->signingKeyId()) +
                   ", every message received must verify");
  }
  receive_stop_ = false;
  receive_thread_ = std::thread(&LcmService::receiveLoop, this);
  running_ = true;
}

void LcmService::stop() {
  if (!running_) return;
  running_ = false;
  core_->cancelBatches();  // first: a whole RTR solve stops at its next iteration
  receive_stop_ = true;
  receive_thread_.join();
  receive_->unsubscribeAll();
  core_->stop();
  summary_ = core_->summary();
  summary_.recv_buf_bytes = std::max<std::int64_t>(recv_buf_at_start_, summary_.recv_buf_bytes);
}

status_t LcmService::status() const { return toMessage(core_->status()); }

void LcmService::receiveLoop() {
  // A dead link is noticed, logged and re-created inside handle(); the core is untouched.
  if (datagrams_ == nullptr) {
    while (!receive_stop_) receive_->handle(50);
    return;
  }
  // udpm: each complete message goes onto the memq link and is dispatched at once, so that
  // instance's queue holds one message at most; the kernel's socket buffer is the only backlog.
  const auto dispatch = [this] {
    while (receive_->handle(0) == 1) {
    }
  };
  while (!receive_stop_) {
    datagrams_->receive(
        50, [&](const std::string& channel, const std::uint8_t* data, std::size_t size) {
          receive_->publish(channel, data, static_cast<unsigned>(size));
          dispatch();
        });
    dispatch();  // the link's probe
  }
}

void LcmService::onMeasurement(const lcm::ReceiveBuffer* rbuf, const std::string& channel,
                               MeasurementKind kind, int limit) {
  // Nothing may unwind through liblcm's C frames.
  const char* what = kind == MeasurementKind::kCommand ? "an edge command"
                     : kind == MeasurementKind::kPrior ? "a prior"
                                                       : "an edge";
  try {
    const std::uint8_t* data = static_cast<const std::uint8_t*>(rbuf->data);
    int size = static_cast<int>(rbuf->data_size);
    const int envelope = auth_ ? static_cast<int>(kEnvelopeOverhead) : 0;
    if (size > limit + envelope) {
      core_->refuse(kind, "oversize", "oversize " + channel,
                    "refused a message of " + std::to_string(size) + " bytes on " + channel +
                        ": over its limit of " + std::to_string(limit + envelope) +
                        " bytes (not decoded)");
      return;
    }
    if (!openReceived(channel, &data, &size)) return;
    core_->receive(arrivalFromBytes(kind, data, size));
  } catch (const std::exception& e) {
    core_->logLimited(std::string("receive error ") + what,
                      std::string("error while receiving ") + what + ": " + e.what());
  }
}

void LcmService::onCommand(const lcm::ReceiveBuffer* rbuf, const std::string& channel) {
  try {
    const std::uint8_t* data = static_cast<const std::uint8_t*>(rbuf->data);
    int size = static_cast<int>(rbuf->data_size);
    const int limit =
        options_.message_limits.command + (auth_ ? static_cast<int>(kEnvelopeOverhead) : 0);
    if (size > limit) {
      core_->refuseControl("oversize", "a message of " + std::to_string(size) + " bytes on " +
                                           channel + ": over its limit of " +
                                           std::to_string(limit) + " bytes (not decoded)");
      return;
    }
    if (!openReceived(channel, &data, &size)) return;
    command_t c;
    std::string detail;
    const MessageProblem p = decodeMessage(data, size, &c, &detail);
    if (p != MessageProblem::kNone) {
      core_->refuseControl(toString(p), std::string(toString(p)) + ": " + detail);
      return;
    }
    core_->command(controlCommand(c));
  } catch (const std::exception& e) {
    core_->logLimited("receive error command",
                      std::string("error while receiving a command: ") + e.what());
  }
}

void LcmService::onResendWindow(const lcm::ReceiveBuffer* rbuf, const std::string& channel) {
  try {
    const std::uint8_t* data = static_cast<const std::uint8_t*>(rbuf->data);
    int size = static_cast<int>(rbuf->data_size);
    const int limit =
        options_.message_limits.resend_window + (auth_ ? static_cast<int>(kEnvelopeOverhead) : 0);
    if (size > limit) {
      core_->refuseControl("resend oversize", "a message of " + std::to_string(size) +
                                                  " bytes on " + channel + ": over its limit of " +
                                                  std::to_string(limit) + " bytes (not decoded)");
      return;
    }
    if (!openReceived(channel, &data, &size)) return;
    const ResendDecoding d = decodeResend(data, size);
    if (!d.ok() || d.message.request) {
      const std::string reason = d.ok() ? "kind" : toString(d.problem);
      core_->refuseControl(
          "resend " + reason,
          "resend_t on " + channel + ": " +
              (d.ok() ? std::string("a REQUEST where only WINDOW answers go") : d.detail));
      return;
    }
    core_->windowAnswer(d.message.priors ? MeasurementKind::kPrior : MeasurementKind::kEdge,
                        d.message.sender, d.message.settled);
  } catch (const std::exception& e) {
    core_->logLimited("receive error resend",
                      std::string("error while receiving a resend answer: ") + e.what());
  }
}

void LcmService::setBusKeys(const BusKeyring& keys) {
  if (!auth_) {
    core_->logLine("keys: this service was started without --key; a key takes a restart");
    return;
  }
  auth_->setKeys(keys);
  std::string ids;
  for (std::size_t k = 1; k < keys.size(); ++k)
    ids += ", verifying with " + busKeyIdText(keys[k].id);
  core_->logLine("keys reloaded: signing with key " + busKeyIdText(keys.front().id) + ids);
}

bool LcmService::openReceived(const std::string& channel, const std::uint8_t** data, int* size) {
  if (!auth_) return true;
  const OpenedMessage opened = auth_->open(channel, *data, static_cast<std::size_t>(*size));
  if (opened.problem == AuthProblem::kNone) {
    *data = opened.data;
    *size = static_cast<int>(opened.size);
    return true;
  }
  const std::string reason = toString(opened.problem);
  {
    std::lock_guard<std::mutex> lock(auth_mutex_);
    ++auth_refused_[reason];
  }
  std::int64_t suppressed = 0;
  if (auth_log_.allow("auth " + reason, &suppressed)) {
    core_->logLine(LogLimiter::withSuppressed(
        "refused a message: auth " + reason + ": " + opened.detail + " (not decoded)", suppressed));
  }
  return false;
}

void LcmService::publishBytes(const std::string& channel, const std::vector<std::uint8_t>& bytes) {
  if (auth_) {
    const std::vector<std::uint8_t> sealed = auth_->seal(channel, bytes.data(), bytes.size());
    publish_->publish(channel, sealed.data(), static_cast<unsigned>(sealed.size()));
    return;
  }
  publish_->publish(channel, bytes.data(), static_cast<unsigned>(bytes.size()));
}

void LcmService::publishEstimate(const Estimate& estimate) {
  publishBytes(channels_.estimate, encodeMessage(toMessage(estimate)));
}

void LcmService::publishStatus(const CoreStatus& status) {
  publishBytes(channels_.status, encodeMessage(toMessage(status)));
}

void LcmService::publishCovariance(const CovarianceAnswer& answer) {
  publishBytes(channels_.covariance, encodeMessage(toMessage(answer)));
}

void LcmService::publishResend(const ResendRequest& request) {
  ResendMessage m;
  m.request = true;
  m.priors = request.kind == MeasurementKind::kPrior;
  m.utime = nowMicros();
  m.sender = request.sender;
  m.settled = request.settled;
  m.highest = request.highest;
  m.missing = request.missing;
  publishBytes(channels_.resend, encodeMessage(makeResendMessage(m)));
}

bool LcmService::takeRecovered() { return publish_->takeRecovered(); }

TransportState LcmService::transportState() const {
  TransportState t;
  const LinkCounts r = receive_->counts(), p = publish_->counts();
  t.receive_up = receive_->up();
  t.publish_up = publish_->up();
  t.link_outages = r.outages + p.outages;
  t.publish_failures = p.failed_publishes;
  // Read live: the link may have re-created the socket since start() (0 while it is down).
  t.recv_buf_bytes = options_.udpm_port > 0 ? udpReceiveBufferBytes(options_.udpm_port) : 0;
  if (datagrams_ != nullptr) {
    t.datagrams_refused = datagrams_->refusedByReason();
    t.datagram_partials_dropped = datagrams_->droppedPartials();
  }
  std::lock_guard<std::mutex> lock(auth_mutex_);
  t.auth_refused = auth_refused_;
  return t;
}

}  // namespace arbor::serve
