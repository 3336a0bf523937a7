// The streaming core of `arbor serve`, whatever the transport: the seq intake, the write-ahead
// journal (through a JournalSink), the queue and its burst grouping, the smoother thread with
// the engine, batch polling and reseeds, status counting and the commands' semantics. It speaks
// Arbor's own types (tools/serve/stream_types.h); a transport is an adapter beside it:
//  - inbound, the adapter's receive thread hands every message to receive() (a measurement, or
//    the refusal of its decoder), command() (an operator's command), refuse() / refuseControl()
//    (what it refused before decoding);
//  - outbound, the core publishes estimates, status and covariance answers through the
//    adapter's Publisher.
// LcmService (tools/serve/serve_service.h) is the LCM adapter; tests/streaming_core_test.cc
// drives the core from memory with no transport at all.
//
// Threads: receive() and the other inbound calls come from one thread at a time (the adapter's
// receive thread, serialised by the intake's mutex); the core's own smoother thread takes every
// queued measurement into one update, in the order received (so a burst is absorbed by larger
// updates), journals the update's mark first, applies it, publishes the estimate and polls the
// batch refiner. start() replays the journal with the same grouping (a restart reproduces the
// estimate bit for bit); stop() drains, refines and publishes the final estimate and status.
#pragma once

#include <atomic>
#include <chrono>
#include <condition_variable>
#include <cstdint>
#include <limits>
#include <map>
#include <memory>
#include <mutex>
#include <optional>
#include <ostream>
#include <string>
#include <thread>
#include <vector>

#include "arbor_slam/core/latency_summary.h"
#include "arbor_slam/tools/serve/edge_intake.h"
#include "arbor_slam/tools/serve/gap_tracker.h"
#include "arbor_slam/tools/serve/journal_sink.h"
#include "arbor_slam/tools/serve/log_limiter.h"
#include "arbor_slam/tools/serve/serve_engine.h"
#include "arbor_slam/tools/serve/snapshot_dir.h"
#include "arbor_slam/tools/serve/stream_types.h"

namespace arbor::serve {

/// What the core needs to know of its transport's links for status (all "up" without links).
struct TransportState {
  bool receive_up = true, publish_up = true;
  std::int64_t link_outages = 0;      ///< receive and publish links, so far
  std::int64_t publish_failures = 0;  ///< publishes lost to a link down
  std::int64_t recv_buf_bytes = 0;    ///< the receive socket's buffer (0: none to report)
  /// Datagrams the transport's own receive path refused before any parsing, by reason
  /// (udpm: tools/serve/lcm_datagram.h), and the fragmented messages it dropped unfinished.
  std::map<std::string, std::int64_t> datagrams_refused;
  std::int64_t datagram_partials_dropped = 0;
  /// Messages refused by the authenticated bus before decoding, by reason (bus_auth.h).
  std::map<std::string, std::int64_t> auth_refused;
};

/// The core's counters and figures at one moment (status()); a transport maps them onto its
/// status message (status_t over LCM).
struct CoreStatus {
  std::int64_t utime = 0;  ///< µs since the epoch
  IntakeCounts edges, priors, commands;
  std::map<std::string, std::int64_t> control_refused;  ///< operator commands, by reason
  std::int64_t journal_refused = 0;                     ///< measurements the journal could not take
  std::int64_t backlog_dropped = 0;  ///< measurements dropped unread: max_backlog were waiting
  std::int64_t journal_bytes = 0;
  std::int64_t edge_senders = 0;  ///< edge sender tables held
  /// (sender, edge seq numbers not received) for every edge sender with gaps, sender order.
  std::vector<std::pair<std::int64_t, std::int64_t>> edge_gaps_by_sender;
  GapCounts loss;         ///< loss recovery: the reorder buffer and resend requests (edges, priors)
  std::int64_t held = 0;  ///< journaled measurements waiting for their update mark
  std::int64_t applied = 0, updates = 0, poses = 0, pending = 0;
  std::int64_t smoother_rejected = 0, smoother_duplicates = 0;
  std::int64_t priors_applied = 0, smoother_priors_rejected = 0;
  int components = 0;
  std::int64_t commands_applied = 0, commands_refused = 0;
  std::map<std::string, std::int64_t> command_refusals;  ///< by EdgeSwitchStatus
  int edges_disabled = 0, pairs_disabled = 0;
  bool robust = false;
  OnlineStats robust_stats;     ///< closures_* of the last update
  double inlier_threshold = 0;  ///< c² in use
  std::int64_t last_command_sender = 0, last_command_seq = 0;
  std::string last_command_result;
  std::int64_t last_sender = 0, last_seq = 0;  ///< of the last edge applied
  std::int64_t journal_edges = 0, journal_updates = 0, journal_priors = 0, journal_commands = 0;
  int refinements = 0;
  double refine_F_before = 0, refine_F_after = 0, refine_time_s = 0;
  int batches = 0, batches_skipped = 0, reseeds = 0, journal_reseeds = 0;
  refine::BatchRun last_batch;  ///< the last run (default before any)
  double F = 0;
  int latency_window = 0;  ///< edges the latency figures cover
  LatencySummary latency;  ///< receipt → estimate published, over that window
  TransportState transport;
};

/// The core's outbound seam: how estimates, status and covariance answers leave. Called from
/// the smoother thread (and from start()/stop()), never two at a time.
class Publisher {
 public:
  virtual ~Publisher() = default;
  virtual void publishEstimate(const Estimate& estimate) = 0;
  virtual void publishStatus(const CoreStatus& status) = 0;
  virtual void publishCovariance(const CovarianceAnswer& answer) = 0;
  /// A resend request to one sender (loss recovery; a transport without it ignores it).
  virtual void publishResend(const ResendRequest& /*request*/) {}
  /// True once after the transport lost what was published (a link came back): the next
  /// estimate is then full.
  virtual bool takeRecovered() { return false; }
  virtual TransportState transportState() const { return {}; }
};

struct StreamingOptions {
  bool fsync_before_update = true;  ///< journal: fsync once before each update (its edges)
  int full_every = 0;  ///< estimates: 0 changed poses only; 1 always full; N full every N
  SmootherOptions smoother;
  bool refine_on_exit = true;  ///< stop(): relinearise everything and iterate to convergence
  /// The exit refinement's time: once it has run this long it stops at its next check (between
  /// relinearise-all iterations and graduation updates; an iteration is never cut), so stop()
  /// returns within the budget plus one iteration. Infinity (the library's default, so that the
  /// final estimate does not depend on the machine's speed): to convergence, however long;
  /// `arbor serve` defaults to 1 s (--exit-refine-budget).
  double exit_refine_budget_s = std::numeric_limits<double>::infinity();
  /// Cancels the exit refinement at its next check (a second SIGINT/SIGTERM: cancelExit()).
  /// Copies share the flag; tests cut it deterministically with cancelAfterChecks.
  CancellationToken exit_refine_cancel;
  int dim = 0;  ///< 2 or 3 fixes the stream's dimension; 0: the first edge's
  /// Seqs remembered per sender for exact duplicate detection; older ones are refused as stale.
  std::int64_t intake_window = EdgeIntake::kDefaultWindow;
  double status_period_s = 1.0;
  int latency_window = 1000;  ///< status latency figures cover the last this many edges
  /// kind, every (0: only on command BATCH), reseed; its cancel token is replaced by the
  /// core's own, which stop() cancels.
  refine::RefinerOptions batch;
  /// Where command SNAPSHOT writes its file (a plain name inside it); "" = SNAPSHOT refused.
  std::string snapshot_dir;
  std::size_t max_senders = EdgeIntake::kDefaultMaxSenders;  ///< sender tables per stream
  /// Loss recovery (tools/serve/gap_tracker.h): an edge or prior that arrives after a gap in its
  /// sender's seqs waits up to this long for the gap to be resent, so the stream is applied in
  /// seq order; 0 (the library's default): off, applied as received, nothing requested;
  /// `arbor serve` defaults to 2 s (--gap-hold).
  std::chrono::milliseconds gap_hold{0};
  std::size_t reorder_limit = 4096;  ///< messages held per sender and stream (then a gap goes)
  /// Resend requests (and acknowledgements) go out at most this often per sender and stream.
  std::chrono::milliseconds resend_period{200};
  std::size_t max_queued_commands = 64;  ///< commands waiting for the smoother; more refused
  /// The receive backlog: edges, priors and edge commands accepted and journaled but not yet
  /// taken by the smoother thread. While this many wait, a message that arrives is dropped
  /// before the intake reads it (never journaled, so its sender's seq shows a gap and loss
  /// recovery can bring it back) and counted in backlog_dropped. What the journal holds is
  /// always applied.
  std::size_t max_backlog = 1 << 18;
  std::ostream* log = nullptr;  ///< log lines (rejections, gaps, errors); nullptr: silent
  /// Lines a sender can provoke (refusals, gaps): at most one per reason per this period, with
  /// the count of those held back; 0: every line.
  std::chrono::milliseconds log_period{1000};
  /// Online robust smoothing of the loop closures (--robust); none: off. Per edge, its trust
  /// and kernel refine it.
  std::optional<RobustOptions> robust;
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
  /// The exit refinement: iterations run, and whether its budget or cancelExit() cut it short
  /// (its estimate is then that of the last iteration completed).
  int exit_refine_iterations = 0;
  bool exit_refine_cut = false;
  double exit_refine_time_s = 0;
  int batches_skipped = 0, reseeds = 0, journal_reseeds = 0;
  std::vector<refine::BatchRun> batches;  ///< every batch run completed, in order
  double F_final = 0;
  /// With robust smoothing: every loop closure at the end, the threshold c² in use.
  std::vector<ClosureReport> closures;
  double inlier_threshold = 0;
  LatencySummary latency;            ///< receipt → estimate published, every edge applied
  LatencySummary transport;          ///< edge utime → receipt (meaningful when clocks agree)
  Estimate final_estimate;           ///< full
  std::int64_t journal_refused = 0;  ///< measurements refused: the journal could not take them
  std::int64_t backlog_dropped = 0;  ///< dropped unread: max_backlog measurements were waiting
  GapCounts loss;                    ///< loss recovery (edges and priors)
  std::int64_t held_at_stop = 0;     ///< journaled, not applied: their update mark did not fit
  JournalDamage journal_damaged;     ///< what the replay at start found damaged and skipped
  std::int64_t link_outages = 0;     ///< receive and publish links
  std::map<std::string, std::int64_t> control_refused;  ///< operator command refusals by reason
  std::int64_t recv_buf_bytes = 0;  ///< the transport's receive buffer (TransportState)
  std::map<std::string, std::int64_t> datagrams_refused;  ///< by reason (TransportState)
  std::int64_t datagram_partials_dropped = 0;             ///< (TransportState)
  std::map<std::string, std::int64_t> auth_refused;       ///< by reason (TransportState)
};

class StreamingCore {
 public:
  /// `publisher` must outlive the core; `journal` may be null (no journal).
  StreamingCore(Publisher& publisher, std::unique_ptr<JournalSink> journal,
                StreamingOptions options);
  ~StreamingCore();
  StreamingCore(const StreamingCore&) = delete;
  StreamingCore& operator=(const StreamingCore&) = delete;

  /// Replays the journal (if any), publishes the replayed estimate and starts the smoother
  /// thread; the transport starts receiving after it. Throws std::runtime_error if the journal
  /// cannot be used.
  void start();
  /// Cancels a batch in flight (its run is kept, marked cancelled, without a reseed): the first
  /// step of stopping, before the transport stops receiving.
  void cancelBatches();
  /// Cuts the exit refinement at its next check and cancels a batch in flight (a second
  /// SIGINT/SIGTERM while stop() runs). Any thread.
  void cancelExit();
  /// After the transport stopped receiving: cancels a batch in flight, applies every queued
  /// measurement in one last update, refines (option), flushes the journal, publishes the final
  /// full estimate and status, joins the smoother thread and fills summary().
  void stop();
  bool running() const { return running_; }

  /// One message of a measurement stream: counted and logged when refused, else journaled
  /// before it is queued (a measurement the journal cannot take is refused: "journal").
  void receive(const Arrival& arrival);
  /// A message of `kind` the transport refused before decoding it (e.g. "oversize"): counted
  /// under `reason`, `line` logged (at most once a second per key).
  void refuse(MeasurementKind kind, const std::string& reason, const std::string& key,
              const std::string& line);
  /// An operator's command, carried out on the smoother thread in the order received; refused
  /// as "queue full" beyond max_queued_commands waiting.
  void command(const ControlCommand& command);
  /// An operator's command refused by the transport (counted under `reason`, logged).
  void refuseControl(const std::string& reason, const std::string& detail);
  /// A sender's answer to a resend request (resend_t WINDOW): it holds nothing of `kind` at or
  /// below `settled`, so the gaps there are given up (counted, logged).
  void windowAnswer(MeasurementKind kind, std::int64_t sender, std::int64_t settled);

  CoreStatus status() const;
  /// After stop(): the whole run.
  const ServeSummary& summary() const { return summary_; }
  /// After stop(): writes the final estimate (Engine::writeEstimate: g2o with the edges
  /// applied, TUM stamped with the edges' utime, or KITTI); false when there is no estimate (no
  /// edge was applied). Throws FileError if it cannot be written.
  bool writeEstimate(const std::string& path, TrajectoryFormat format) const;

  void logLine(const std::string& line);
  /// Measurements waiting for the smoother thread now (at most max_backlog, and the batch of a
  /// held update put back).
  std::size_t backlog();
  /// A line that a sender can provoke at will: at most one per `key` a second.
  void logLimited(const std::string& key, const std::string& line);

 private:
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
  /// An accepted measurement as queued, received at `received` (transport_ms from now).
  static Queued queued(IntakeResult accepted, std::chrono::steady_clock::time_point received);

  void smootherLoop();
  /// Journals and queues accepted measurements, in order (caller holds intake_mutex_): a
  /// measurement the journal cannot take is revoked and refused ("journal").
  void commit(std::vector<IntakeResult> accepted, std::chrono::steady_clock::time_point received);
  /// Loss recovery on the smoother thread: gaps that waited --gap-hold given up, and the resend
  /// requests due published.
  void recoverLosses();
  void logGivenUp(std::int64_t seqs, const std::string& why);
  /// Logs (rate-limited) the sender table `r`'s arrival evicted and the held messages it dropped.
  void logIntakeNotes(const IntakeResult& r, const char* what);
  /// --solve-budget-mb: while nothing waits in the queue, solves the cliques the budget deferred,
  /// one budget's worth at a time (a measurement that arrives waits one slice at most), and
  /// publishes the poses they moved.
  void solveDeferredWhileIdle();
  void replayJournal();
  /// False when the update could not be journaled (nothing applied; the caller holds it).
  bool applyBatch(std::vector<Queued>& batch, bool from_journal);
  void applyEdgeCommand(const Queued& q, bool from_journal);
  /// A refinement to convergence (command REFINE, journaled before it runs) or, replayed from
  /// the journal, as its mark says (`cut` > 0: cut short after cut − 1 checks).
  void refine(bool from_journal, int cut = 0);
  /// stop()'s refinement: within exit_refine_budget_s, journaled after it ran with its cut.
  void refineOnExit();
  struct Refinement {
    UpdateStats stats;
    double F_before = 0, F_after = 0, seconds = 0;
  };
  /// The engine's refinement (stopped by `cancel` when given), timed and recorded in the status
  /// (refinements, refine_F_before/after, refine_time_s, F): refine's and refineOnExit's.
  Refinement runRefinement(const CancellationToken* cancel);
  /// Collects a finished batch (`wait`: the one in flight), journals and applies its reseed,
  /// publishes a status (and with `publish` the estimate if it reseeded); returns whether a run
  /// was collected.
  bool pollBatch(bool wait, bool publish);
  void startBatch(bool on_command);
  void applyReseed(const Estimate& seed, bool from_journal, refine::BatchRun* run);
  void handleCommand(const ControlCommand& command);
  void writeSnapshot(const ControlCommand& command);
  /// Command CLOSURES: the closure report into the snapshot directory (SNAPSHOT's rules).
  void writeClosures(const ControlCommand& command);
  void publishCovariance(const ControlCommand& command);
  void ensureEngine(int dim);
  void publishEstimate(bool full);
  void publishStatus();
  /// Journals an update of `n` measurements (mark, then the group fsync); false when the
  /// journal cannot take the mark (the update must wait).
  bool journalUpdate(int n);

  Publisher& publisher_;
  std::unique_ptr<JournalSink> journal_;
  StreamingOptions options_;
  SnapshotDir snapshots_;
  LogLimiter limiter_;

  // The receive side (and the journal replay before the smoother starts).
  mutable std::mutex intake_mutex_;
  EdgeIntake intake_;
  GapTracker gaps_;
  std::chrono::steady_clock::time_point last_requests_;
  std::int64_t journal_refused_ = 0;
  std::int64_t backlog_dropped_ = 0;
  std::map<std::string, std::int64_t> control_refused_;  ///< by reason

  // Hand-over between the threads.
  std::mutex queue_mutex_;
  std::condition_variable queue_cv_;
  std::vector<Queued> queue_;
  std::vector<ControlCommand> commands_;
  bool smoother_stop_ = false;
  /// An update whose mark the journal could not take waits until then before it is tried again.
  std::chrono::steady_clock::time_point hold_until_;
  std::atomic<std::int64_t> held_{0};  ///< measurements held so (status)

  // Smoother thread; the figures status() reads are under state_mutex_.
  std::unique_ptr<Engine> engine_;
  mutable std::mutex state_mutex_;
  CoreStatus state_;  ///< the smoother's counters (its intake fields unused)
  std::vector<refine::BatchRun> batch_runs_;
  struct ExitRefinement {
    int iterations = 0;
    bool cut = false;
    double seconds = 0;
  } exit_refine_;                     ///< stop()'s refinement (state_mutex_)
  std::vector<double> latencies_ms_;  ///< every applied edge and prior
  std::vector<double> transport_ms_;  ///< every applied edge and prior
  std::chrono::steady_clock::time_point last_status_;

  std::mutex log_mutex_;
  std::mutex publish_mutex_;
  std::thread smoother_thread_;
  bool running_ = false;
  ServeSummary summary_;
};

}  // namespace arbor::serve
