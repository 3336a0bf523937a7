// `arbor serve` over LCM: the LCM adapter of the streaming core (tools/serve/streaming_core.h).
// The core holds everything that is not LCM's — the intake, the queue and its burst grouping,
// the smoother thread, batches, status counting, the commands' semantics, the journal's
// write-ahead rules. This adapter holds what is: the two LinkWatch links (one receives, one
// publishes; tools/serve/link_watch.h: a dead hub is noticed and the instance re-created with
// backoff, the core's state untouched), over udpm:// its own datagram receiver
// (tools/serve/udpm_receiver.h) in place of liblcm's, the subscriptions and the receive thread that
// decodes edge_t, prior_t, edge_command_t and command_t (size limits first, then
// io/lcm_messages.h's checked decoders) and hands them to the core, the publishing of estimate_t,
// status_t and covariance_t, and the journal as an LCM event log (tools/serve/lcm_event_journal.h).
// docs/lcm.md is the user's view; docs/service-internals.md, "Adding a transport", the structure.
#pragma once

#include <atomic>
#include <cstdint>
#include <map>
#include <memory>
#include <mutex>
#include <string>
#include <thread>
#include <vector>

#include <lcm/lcm-cpp.hpp>

#include "arbor_slam/io/lcm_messages.h"
#include "arbor_slam/tools/serve/bus_auth.h"
#include "arbor_slam/tools/serve/lcm_channels.h"
#include "arbor_slam/tools/serve/link_watch.h"
#include "arbor_slam/tools/serve/log_limiter.h"
#include "arbor_slam/tools/serve/streaming_core.h"
#include "arbor_slam/tools/serve/udpm_receiver.h"

namespace arbor::serve {

/// Largest message accepted per channel, in bytes; a larger one is refused before it is decoded
/// ("oversize"). The defaults are far above what a valid message needs (a 3D edge_t is 300
/// bytes, a prior_t under 400, an edge_command_t under 100).
struct MessageLimits {
  int edge = 4096;
  int prior = 4096;
  int edge_command = 1024;
  int command = 4096;       ///< command_t (its path is a file name)
  int resend_window = 256;  ///< resend_t WINDOW (no ranges: 50 bytes)
};

/// The core's options and the LCM adapter's own.
struct ServeOptions : StreamingOptions {
  std::string channel_prefix;
  std::string journal_path;    ///< "" = no journal
  int fsync_interval_ms = -1;  ///< 0: fsync every edge; > 0: at most every N ms; < 0: never
  MessageLimits message_limits;
  std::int64_t journal_max_bytes = 0;  ///< > 0: the journal is full at this size (disk quota)
  /// Journal room only update marks may use (EventLogWriterOptions::reserve_bytes), so the
  /// measurements journaled before the disk filled can still be applied.
  std::int64_t journal_reserve_bytes = 16384;
  /// udpm: the port the receive instance listens on; start() reads that socket's SO_RCVBUF for
  /// status_t's recv_buf_bytes (serve::udpReceiveBufferBytes). <= 0: not udpm.
  int udpm_port = -1;
  /// The deployment key (tools/serve/bus_key.h; empty: none). With it every message received is
  /// an envelope checked before it is decoded (refusals counted by reason, "auth ..."), and every
  /// message published is sealed (tools/serve/bus_auth.h).
  BusKeyring bus_keys;
};

class LcmService final : public Publisher {
 public:
  /// `lcm` must outlive the service; it may be shared (memq:// in tests). Borrowed instances are
  /// watched but never re-created.
  LcmService(lcm::LCM& lcm, ServeOptions options);
  /// Receives on `receive` and publishes on `publish`. Over tcpq:// they should be two
  /// instances: liblcm 1.3 delays what an instance receives (by up to its handle timeout) while
  /// another thread publishes on it.
  LcmService(lcm::LCM& receive, lcm::LCM& publish, ServeOptions options);
  /// Receives and publishes through links that re-create their instances after a fault; both
  /// must outlive the service. `receive` should have a probe channel (channels().link_probe).
  /// With `datagrams` (udpm://; must outlive the service) the receive thread reads the datagrams
  /// itself, and publishes each complete message onto `receive`, a memq:// link, whose
  /// subscriptions dispatch it: liblcm never parses a datagram (tools/serve/udpm_receiver.h).
  LcmService(LinkWatch& receive, LinkWatch& publish, ServeOptions options,
             UdpmReceiver* datagrams = nullptr);
  ~LcmService() override;
  LcmService(const LcmService&) = delete;
  LcmService& operator=(const LcmService&) = delete;

  /// Replays the journal (if any), publishes the replayed estimate, subscribes and starts the
  /// receive and smoother threads. Throws std::runtime_error if the journal cannot be used.
  void start();
  /// Cancels a batch in flight (its run is kept, marked cancelled, without a reseed), stops
  /// receiving, then stops the core: every queued edge in one last update, refinement (option),
  /// the journal flushed, the final full estimate and status published, the threads joined.
  void stop();
  /// Cuts the exit refinement of a stop() in progress at its next check and cancels a batch in
  /// flight (StreamingCore::cancelExit; a second SIGINT/SIGTERM). Any thread.
  void cancelExit() { core_->cancelExit(); }
  /// With a key: replaces the keys (the key file read again; tools/serve/bus_key.h) and logs
  /// their ids; the replay windows stay. Without one: logs that keys need --key at start. Any
  /// thread.
  void setBusKeys(const BusKeyring& keys);
  /// Counters and figures so far (thread-safe).
  status_t status() const;
  /// After stop(): the whole run.
  const ServeSummary& summary() const { return summary_; }
  /// After stop(): StreamingCore::writeEstimate.
  bool writeEstimate(const std::string& path, TrajectoryFormat format) const {
    return core_->writeEstimate(path, format);
  }
  const Channels& channels() const { return channels_; }
  /// The channels the service subscribes to on its receive link (Channels::received() is what
  /// a udpm receiver must reassemble for it).
  std::vector<std::string> subscribedChannels() const { return receive_->channels(); }

  // Publisher: the core's estimates, status and answers onto the publish link.
  void publishEstimate(const Estimate& estimate) override;
  void publishStatus(const CoreStatus& status) override;
  void publishCovariance(const CovarianceAnswer& answer) override;
  void publishResend(const ResendRequest& request) override;
  bool takeRecovered() override;
  TransportState transportState() const override;

 private:
  /// With a key: the receive link's probe sealed and opened as every other message.
  void sealProbes();
  LcmService(LinkWatch* receive, LinkWatch* publish, ServeOptions options, UdpmReceiver* datagrams);
  void onMeasurement(const lcm::ReceiveBuffer* rbuf, const std::string& channel,
                     MeasurementKind kind, int limit);
  void onCommand(const lcm::ReceiveBuffer* rbuf, const std::string& channel);
  /// A publisher's resend_t WINDOW answer (any other kind or a bad message: counted, logged).
  void onResendWindow(const lcm::ReceiveBuffer* rbuf, const std::string& channel);
  void receiveLoop();
  void publishBytes(const std::string& channel, const std::vector<std::uint8_t>& bytes);
  /// With a key: opens the envelope of a message received on `channel` (true, `*data` and
  /// `*size` then the message inside), else counts and logs the refusal (false).
  bool openReceived(const std::string& channel, const std::uint8_t** data, int* size);

  std::unique_ptr<LinkWatch> owned_receive_, owned_publish_;  ///< over borrowed instances
  LinkWatch* receive_;                                        ///< receive (subscriptions, handle)
  LinkWatch* publish_;                                        ///< estimates and status
  UdpmReceiver* datagrams_;  ///< udpm: what `receive_` gets its messages from (else null)
  ServeOptions options_;
  Channels channels_;
  std::unique_ptr<StreamingCore> core_;
  std::atomic<bool> receive_stop_{false};
  std::thread receive_thread_;
  std::atomic<std::int64_t> recv_buf_at_start_{0};
  bool running_ = false;
  ServeSummary summary_;
  std::unique_ptr<BusAuth> auth_;  ///< with a key (else null)
  mutable std::mutex auth_mutex_;
  std::map<std::string, std::int64_t> auth_refused_;  ///< by reason (under auth_mutex_)
  LogLimiter auth_log_;
};

/// `arbor serve`'s service: the streaming core over LCM.
using Service = LcmService;

}  // namespace arbor::serve
