// `arbor serve` as a library: edges, priors and edge commands in over LCM, estimates and status
// out. One thread receives and validates (EdgeIntake), journals each accepted edge, prior or edge
// command and queues it; one
// thread runs the smoother and, when it falls behind, takes everything queued into a single
// update (in the order received), so latency stays bounded under bursts. With a journal (an LCM
// event log) every accepted edge and prior is written before it is applied, with marks of the
// update grouping; start() replays an existing journal in file order with the same grouping, so
// a restart after kill -9 reproduces the estimate exactly.
//
// Faults (docs/lcm.md, "Faults"): the transport is two LinkWatch links (tools/serve/link_watch.h)
// that notice a dead hub, keep every bit of the service's state and re-create themselves with
// backoff. The journal is written ahead: a measurement the journal cannot take (full disk) is
// refused and counted, and an update whose mark the journal cannot take is held (its
// measurements stay queued, in the journal) until the mark fits. Nothing from the bus writes a
// file outside --snapshot-dir or overwrites a file the service did not create; sender tables,
// message sizes and queued commands are bounded, and every refusal is counted in status_t and
// logged at most once a second per reason (LogLimiter).
//
// Batch refinement (tools/refine/batch_refiner.h): every `batch.every` updates, or on command
// BATCH, a snapshot is solved in the background while edges keep flowing; the smoother thread
// polls for the result between updates. With `batch.reseed` a winning batch estimate becomes the
// linearisation point; the complete new point is journaled (an estimate_t on
// ARBOR_JOURNAL_RESEED) before it is applied, and replayed from there, so restarts stay exact.
#pragma once

#include <atomic>
#include <chrono>
#include <condition_variable>
#include <cstdint>
#include <map>
#include <memory>
#include <mutex>
#include <optional>
#include <ostream>
#include <string>
#include <thread>
#include <vector>

#include <lcm/lcm-cpp.hpp>

#include "arbor/io/lcm_journal.h"
#include "arbor/io/lcm_messages.h"
#include "arbor/tools/cli/latency.h"
#include "arbor/tools/serve/edge_intake.h"
#include "arbor/tools/serve/link_watch.h"
#include "arbor/tools/serve/log_limiter.h"
#include "arbor/tools/serve/serve_engine.h"
#include "arbor/tools/serve/snapshot_dir.h"

namespace arbor::serve {

struct Channels {
  std::string edges, estimate, status, command, priors, edge_commands;
  std::string link_probe;  ///< the receive link's own probe (LinkWatch)
  std::string covariance;  ///< answers to command COVARIANCE
  /// ARBOR_EDGES, ARBOR_ESTIMATE, ARBOR_STATUS, ARBOR_COMMAND, ARBOR_PRIORS,
  /// ARBOR_EDGE_COMMANDS, ARBOR_LINK_PROBE, ARBOR_COVARIANCE, each after `prefix`.
  static Channels withPrefix(const std::string& prefix);
};

/// Largest message accepted per channel, in bytes; a larger one is refused before it is decoded
/// ("oversize"). The defaults are far above what a valid message needs (a 3D edge_t is 300
/// bytes, a prior_t under 400, an edge_command_t under 100).
struct MessageLimits {
  int edge = 4096;
  int prior = 4096;
  int edge_command = 1024;
  int command = 4096;  ///< command_t (its path is a file name)
};

struct ServeOptions {
  std::string channel_prefix;
  std::string journal_path;         ///< "" = no journal
  int fsync_interval_ms = -1;       ///< 0: fsync every edge; > 0: at most every N ms; < 0: never
  bool fsync_before_update = true;  ///< fsync once before each update (covers its edges)
  int full_every = 0;  ///< estimates: 0 changed poses only; 1 always full; N full every N
  SmootherOptions smoother;
  bool refine_on_exit = true;  ///< stop(): relinearise everything and iterate to convergence
  int dim = 0;                 ///< 2 or 3 fixes the stream's dimension; 0: the first edge's
  /// Seqs remembered per sender for exact duplicate detection; older ones are refused as stale.
  std::int64_t intake_window = EdgeIntake::kDefaultWindow;
  double status_period_s = 1.0;
  int latency_window = 1000;  ///< status latency figures cover the last this many edges
  /// kind, every (0: only on command BATCH), reseed; its cancel token is replaced by the
  /// service's own, which stop() cancels.
  refine::RefinerOptions batch;
  /// Where command SNAPSHOT writes its file (a plain name inside it); "" = SNAPSHOT refused.
  std::string snapshot_dir;
  std::size_t max_senders = EdgeIntake::kDefaultMaxSenders;  ///< sender tables per stream
  MessageLimits message_limits;
  std::size_t max_queued_commands = 64;  ///< command_t waiting for the smoother; more refused
  std::int64_t journal_max_bytes = 0;    ///< > 0: the journal is full at this size (disk quota)
  /// Journal room only update marks may use (EventLogWriterOptions::reserve_bytes), so the
  /// measurements journaled before the disk filled can still be applied.
  std::int64_t journal_reserve_bytes = 16384;
  std::ostream* log = nullptr;  ///< log lines (rejections, gaps, errors); nullptr: silent
  /// Lines a sender can provoke (refusals, gaps): at most one per reason per this period, with
  /// the count of those held back; 0: every line.
  std::chrono::milliseconds log_period{1000};
  /// Online robust smoothing of the loop closures (--robust); none: off. Per edge, edge_t's
  /// trust and kernel refine it.
  std::optional<RobustOptions> robust;
  /// udpm: the port the receive instance listens on; start() reads that socket's SO_RCVBUF for
  /// status_t's recv_buf_bytes (serve::udpReceiveBufferBytes). <= 0: not udpm.
  int udpm_port = -1;
};

struct ServeSummary {
  IntakeCounts intake;        ///< edges
  IntakeCounts prior_intake;  ///< priors
  std::int64_t applied = 0;   ///< edges taken into updates
  std::int64_t priors_applied = 0;
  std::int64_t smoother_priors_rejected = 0;  ///< priors the smoother refused
  std::int64_t journal_priors = 0;            ///< replayed from the journal at start
  int components = 0;                         ///< connected components at the end
  IntakeCounts command_intake;                ///< edge commands
  std::int64_t commands_applied = 0;          ///< handed to the smoother
  std::int64_t commands_refused = 0;          ///< refused by the smoother (by reason below)
  std::map<std::string, std::int64_t> commands_refused_by_reason;
  std::int64_t journal_commands = 0;  ///< replayed from the journal at start
  int edges_disabled = 0, pairs_disabled = 0;
  std::int64_t updates = 0;
  std::int64_t poses = 0;
  std::int64_t pending = 0;
  std::int64_t smoother_rejected = 0, smoother_duplicates = 0;
  std::int64_t journal_edges = 0, journal_updates = 0;  ///< replayed from the journal at start
  int refinements = 0;
  int batches_skipped = 0, reseeds = 0, journal_reseeds = 0;
  std::vector<refine::BatchRun> batches;  ///< every batch run completed, in order
  double F_final = 0;
  /// With robust smoothing: every loop closure at the end, the threshold c² in use.
  std::vector<ClosureReport> closures;
  double inlier_threshold = 0;
  cli::LatencySummary latency;       ///< receipt → estimate published, every edge applied
  cli::LatencySummary transport;     ///< edge utime → receipt (meaningful when clocks agree)
  estimate_t final_estimate;         ///< full
  std::int64_t journal_refused = 0;  ///< measurements refused: the journal could not take them
  std::int64_t held_at_stop = 0;     ///< journaled, not applied: their update mark did not fit
  std::int64_t link_outages = 0;     ///< receive and publish links
  std::map<std::string, std::int64_t> control_refused;  ///< command_t refusals by reason
  std::int64_t recv_buf_bytes = 0;  ///< udpm: the receive socket's SO_RCVBUF (status_t's)
};

class Service {
 public:
  /// `lcm` must outlive the service; it may be shared (memq:// in tests). Borrowed instances are
  /// watched but never re-created.
  Service(lcm::LCM& lcm, ServeOptions options);
  /// Receives on `receive` and publishes on `publish`. Over tcpq:// they should be two
  /// instances: liblcm 1.3 delays what an instance receives (by up to its handle timeout) while
  /// another thread publishes on it.
  Service(lcm::LCM& receive, lcm::LCM& publish, ServeOptions options);
  /// Receives and publishes through links that re-create their instances after a fault; both
  /// must outlive the service. `receive` should have a probe channel (channels().link_probe).
  Service(LinkWatch& receive, LinkWatch& publish, ServeOptions options);
  ~Service();
  Service(const Service&) = delete;
  Service& operator=(const Service&) = delete;

  /// Replays the journal (if any), publishes the replayed estimate, subscribes and starts the
  /// receive and smoother threads. Throws std::runtime_error if the journal cannot be used.
  void start();
  /// Stops receiving, cancels a batch in flight (its run is kept, marked cancelled, without a
  /// reseed), applies every queued edge in one last update, refines (option), flushes the
  /// journal, publishes the final full estimate and status, joins the threads.
  void stop();
  /// Counters and figures so far (thread-safe).
  status_t status() const;
  /// After stop(): the whole run.
  const ServeSummary& summary() const { return summary_; }
  /// After stop(): writes the final estimate and the edges applied as g2o; false when there is
  /// no estimate (no edge was applied). Throws FileError if it cannot be written.
  bool writeG2o(const std::string& path) const;
  const Channels& channels() const { return channels_; }

 private:
  Service(LinkWatch* receive, LinkWatch* publish, ServeOptions options);
  struct Queued {
    bool is_prior = false;
    bool is_command = false;
    AnyStreamEdge edge;         ///< when neither
    AnyStreamPrior prior;       ///< when is_prior
    StreamEdgeCommand command;  ///< when is_command
    std::int64_t sender = 0, seq = 0;
    std::chrono::steady_clock::time_point received;
    double transport_ms = 0;  ///< receipt − the message's utime (wall clocks; same host: transport)
  };
  /// An accepted edge or prior as queued, received at `received` (transport_ms from now).
  static Queued queued(IntakeResult accepted, std::chrono::steady_clock::time_point received);

  void onEdge(const lcm::ReceiveBuffer* rbuf, const std::string& channel);
  void onCommand(const lcm::ReceiveBuffer* rbuf, const std::string& channel);
  void onPrior(const lcm::ReceiveBuffer* rbuf, const std::string& channel);
  void onEdgeCommand(const lcm::ReceiveBuffer* rbuf, const std::string& channel);
  enum class Incoming { kEdge, kPrior, kCommand };
  /// Admits, journals and queues one edge_t, prior_t or edge_command_t.
  void receiveMeasurement(const lcm::ReceiveBuffer* rbuf, const std::string& channel,
                          Incoming kind);
  /// Hands an edge command to the smoother (counted, logged live).
  void applyEdgeCommand(const Queued& q, bool from_journal);
  void receiveCommand(const lcm::ReceiveBuffer* rbuf, const std::string& channel);
  void receiveLoop();
  void smootherLoop();
  void replayJournal();
  /// False when the update could not be journaled (nothing applied; the caller holds it).
  bool applyBatch(std::vector<Queued>& batch, bool from_journal);
  void refine(bool from_journal);
  /// Collects a finished batch (`wait`: the one in flight), journals and applies its reseed,
  /// publishes a status (and with `publish` the estimate if it reseeded); returns whether a run
  /// was collected.
  bool pollBatch(bool wait, bool publish);
  void startBatch(bool on_command);
  void applyReseed(const estimate_t& seed, bool from_journal, refine::BatchRun* run);
  void handleCommand(const command_t& command);
  /// Command CLOSURES: the closure report into --snapshot-dir (SNAPSHOT's rules).
  void writeClosures(const command_t& command);
  /// Command COVARIANCE: the covariance of the ids in its path, or the refusal, on
  /// channels_.covariance.
  void publishCovariance(const command_t& command);
  void ensureEngine(int dim);
  void publishEstimate(bool full);
  void publishStatus();
  void writeMark(std::int8_t kind, int edges);
  /// Journals an update of `n` measurements (mark, then the group fsync); false when the
  /// journal cannot take the mark (the update must wait).
  bool journalUpdate(int n);
  void writeSnapshot(const command_t& c);
  /// Whether a message of `size` bytes fits `limit`; counts and logs an oversize one.
  bool fitsLimit(int size, int limit, const std::string& channel, EdgeIntake::Kind kind);
  void refuseControl(const std::string& reason, const std::string& detail);
  void logLine(const std::string& line);
  /// A line that a sender can provoke at will: at most one per `key` a second.
  void logLimited(const std::string& key, const std::string& line);

  std::unique_ptr<LinkWatch> owned_receive_, owned_publish_;  ///< over borrowed instances
  LinkWatch* receive_;                                        ///< receive (subscriptions, handle)
  LinkWatch* publish_;                                        ///< estimates and status
  ServeOptions options_;
  Channels channels_;
  std::unique_ptr<EventLogWriter> journal_;
  SnapshotDir snapshots_;
  LogLimiter limiter_;

  // Receive thread (and the journal replay before it starts); counts read under intake_mutex_.
  mutable std::mutex intake_mutex_;
  EdgeIntake intake_;
  std::int64_t journal_refused_ = 0;
  std::map<std::string, std::int64_t> control_refused_;  ///< command_t, by reason

  // Hand-over between the threads.
  std::mutex queue_mutex_;
  std::condition_variable queue_cv_;
  std::vector<Queued> queue_;
  std::vector<command_t> commands_;
  bool smoother_stop_ = false;
  /// An update whose mark the journal could not take waits until then before it is tried again.
  std::chrono::steady_clock::time_point hold_until_;
  std::atomic<std::int64_t> held_{0};  ///< measurements held so (status)
  std::atomic<bool> receive_stop_{false};

  // Smoother thread; the figures status() reads are under state_mutex_.
  std::unique_ptr<Engine> engine_;
  mutable std::mutex state_mutex_;
  std::int64_t applied_ = 0, updates_ = 0, poses_ = 0, pending_ = 0;
  std::int64_t smoother_rejected_ = 0, smoother_duplicates_ = 0;
  std::int64_t priors_applied_ = 0, smoother_priors_rejected_ = 0;
  int components_ = 0;
  std::int64_t commands_applied_ = 0, commands_refused_ = 0, journal_commands_ = 0;
  std::map<std::string, std::int64_t> command_refusals_;  ///< by EdgeSwitchStatus
  int edges_disabled_ = 0, pairs_disabled_ = 0;
  OnlineStats robust_stats_;     ///< closures_* of the last update (robust smoothing)
  double inlier_threshold_ = 0;  ///< c² in use (robust smoothing)
  std::int64_t last_command_sender_ = 0, last_command_seq_ = 0;
  std::string last_command_result_;
  std::int64_t last_sender_ = 0, last_seq_ = 0;  ///< of the last edge applied
  std::int64_t journal_edges_ = 0, journal_updates_ = 0, journal_priors_ = 0;
  int refinements_ = 0;
  double refine_F_before_ = 0, refine_F_after_ = 0, refine_time_s_ = 0;
  std::vector<refine::BatchRun> batch_runs_;
  int batches_skipped_ = 0, reseeds_ = 0, journal_reseeds_ = 0;
  double F_ = 0;
  std::int64_t recv_buf_bytes_ = 0;
  std::vector<double> latencies_ms_;  ///< every applied edge and prior
  std::vector<double> transport_ms_;  ///< every applied edge and prior
  std::chrono::steady_clock::time_point last_status_;

  std::mutex log_mutex_;
  std::mutex publish_mutex_;
  std::thread receive_thread_, smoother_thread_;
  bool running_ = false;
  ServeSummary summary_;
};

/// Microseconds since the epoch (message utime).
std::int64_t nowMicros();

}  // namespace arbor::serve
