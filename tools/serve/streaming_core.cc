#include "arbor_slam/tools/serve/streaming_core.h"

#include <algorithm>
#include <cmath>
#include <deque>
#include <iterator>
#include <optional>
#include <sstream>
#include <stdexcept>

#include "arbor_slam/tools/serve/closure_report.h"

namespace arbor::serve {
namespace {

double msSince(std::chrono::steady_clock::time_point t) {
  return std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - t).count();
}

const char* nameOf(MeasurementKind kind) {
  return kind == MeasurementKind::kCommand ? "edge command"
         : kind == MeasurementKind::kPrior ? "prior"
                                           : "edge";
}

}  // namespace

std::int64_t nowMicros() {
  return std::chrono::duration_cast<std::chrono::microseconds>(
             std::chrono::system_clock::now().time_since_epoch())
      .count();
}

StreamingCore::StreamingCore(Publisher& publisher, std::unique_ptr<JournalSink> journal,
                             StreamingOptions options)
    : publisher_(publisher),
      journal_(std::move(journal)),
      options_(std::move(options)),
      snapshots_(options_.snapshot_dir),
      limiter_(options_.log_period),
      intake_(options_.dim, options_.intake_window, options_.max_senders),
      gaps_(options_.gap_hold, std::max<std::size_t>(1, options_.reorder_limit),
            std::max<std::int64_t>(1, options_.intake_window)) {
  options_.batch.cancel = CancellationToken();  // the core's own: stop() cancels it
  if (options_.dim != 0 && options_.dim != 2 && options_.dim != 3) {
    throw std::invalid_argument("serve: dim " + std::to_string(options_.dim) + " is not 2 or 3");
  }
  if (options_.batch.every < 0) {
    throw std::invalid_argument("serve: batch every " + std::to_string(options_.batch.every) +
                                " updates is < 0");
  }
  state_.robust = options_.robust.has_value();
}

StreamingCore::~StreamingCore() {
  if (running_) {
    try {
      stop();
    } catch (...) {
    }
  }
}

void StreamingCore::logLine(const std::string& line) {
  if (options_.log == nullptr) return;
  std::lock_guard<std::mutex> lock(log_mutex_);
  *options_.log << "arbor serve: " << line << std::endl;
}

std::size_t StreamingCore::backlog() {
  std::lock_guard<std::mutex> lock(queue_mutex_);
  return queue_.size();
}

void StreamingCore::logLimited(const std::string& key, const std::string& line) {
  std::int64_t suppressed = 0;
  if (limiter_.allow(key, &suppressed)) logLine(LogLimiter::withSuppressed(line, suppressed));
}

void StreamingCore::start() {
  if (running_) throw std::logic_error("serve: start() twice");
  if (journal_) replayJournal();
  // What the journal holds is settled: a restart never asks for it again.
  for (const MeasurementKind kind : {MeasurementKind::kEdge, MeasurementKind::kPrior}) {
    for (const auto& [sender, highest] : intake_.highestBySender(kind))
      gaps_.restore(kind, sender, highest);
  }
  last_requests_ = std::chrono::steady_clock::now();
  if (intake_.dim() == 0) {
    logLine(
        "no --dim and no journaled edge: the first edge or prior received fixes the stream's "
        "dimension, whoever sends it; on a shared bus set --dim 2|3");
  }
  if (engine_) publishEstimate(true);
  last_status_ = std::chrono::steady_clock::now();
  smoother_stop_ = false;
  smoother_thread_ = std::thread(&StreamingCore::smootherLoop, this);
  running_ = true;
}

void StreamingCore::cancelBatches() { options_.batch.cancel.cancel(); }

void StreamingCore::cancelExit() {
  options_.exit_refine_cancel.cancel();
  cancelBatches();
}

void StreamingCore::stop() {
  if (!running_) return;
  running_ = false;
  // A background batch (a whole RTR solve) stops at its next iteration; the batches the last
  // update may still start stop at their first. The cancelled run is collected below, without a
  // reseed.
  cancelBatches();
  {
    // Held for a gap that will not be filled now: journaled and applied in seq order.
    std::lock_guard<std::mutex> lock(intake_mutex_);
    std::int64_t given_up = 0;
    std::vector<IntakeResult> released = gaps_.releaseAll(&given_up);
    if (!released.empty()) {
      logLine("stopping: " + std::to_string(released.size()) +
              " measurements held for a gap released, " + std::to_string(given_up) +
              " seq numbers given up");
    }
    commit(std::move(released), std::chrono::steady_clock::now());
  }
  {
    std::lock_guard<std::mutex> lock(queue_mutex_);
    smoother_stop_ = true;
  }
  queue_cv_.notify_all();
  smoother_thread_.join();

  pollBatch(true, false);  // a batch still running was cancelled: collected, not reseeded
  if (engine_ && options_.refine_on_exit) refineOnExit();
  if (journal_) {
    try {
      journal_->sync();
    } catch (const std::exception& e) {
      logLine(std::string("journal: ") + e.what());
    }
  }
  summary_ = ServeSummary();
  if (journal_) summary_.journal_damaged = journal_->damage();
  if (engine_) {
    publishEstimate(true);
    summary_.final_estimate = engine_->estimate(true);
    summary_.F_final = summary_.final_estimate.F;
    summary_.closures = engine_->closures();
    summary_.inlier_threshold = engine_->inlierThreshold();
  }
  publishStatus();
  {
    std::lock_guard<std::mutex> lock(intake_mutex_);
    summary_.intake = intake_.counts();
    summary_.prior_intake = intake_.priorCounts();
    summary_.command_intake = intake_.commandCounts();
    summary_.journal_refused = journal_refused_;
    summary_.backlog_dropped = backlog_dropped_;
    summary_.control_refused = control_refused_;
    summary_.loss = gaps_.counts();
  }
  const TransportState transport = publisher_.transportState();
  summary_.link_outages = transport.link_outages;
  summary_.recv_buf_bytes = transport.recv_buf_bytes;
  summary_.datagrams_refused = transport.datagrams_refused;
  summary_.datagram_partials_dropped = transport.datagram_partials_dropped;
  summary_.auth_refused = transport.auth_refused;
  {
    std::lock_guard<std::mutex> lock(queue_mutex_);
    summary_.held_at_stop = static_cast<std::int64_t>(queue_.size());
  }
  std::lock_guard<std::mutex> lock(state_mutex_);
  const CoreStatus& s = state_;
  summary_.applied = s.applied;
  summary_.updates = s.updates;
  summary_.poses = s.poses;
  summary_.pending = s.pending;
  summary_.smoother_rejected = s.smoother_rejected;
  summary_.smoother_duplicates = s.smoother_duplicates;
  summary_.journal_edges = s.journal_edges;
  summary_.priors_applied = s.priors_applied;
  summary_.smoother_priors_rejected = s.smoother_priors_rejected;
  summary_.journal_priors = s.journal_priors;
  summary_.components = s.components;
  summary_.commands_applied = s.commands_applied;
  summary_.commands_refused = s.commands_refused;
  summary_.commands_refused_by_reason = s.command_refusals;
  summary_.journal_commands = s.journal_commands;
  summary_.edges_disabled = s.edges_disabled;
  summary_.pairs_disabled = s.pairs_disabled;
  summary_.journal_updates = s.journal_updates;
  summary_.refinements = s.refinements;
  summary_.exit_refine_iterations = exit_refine_.iterations;
  summary_.exit_refine_cut = exit_refine_.cut;
  summary_.exit_refine_time_s = exit_refine_.seconds;
  summary_.batches = batch_runs_;
  summary_.batches_skipped = s.batches_skipped;
  summary_.reseeds = s.reseeds;
  summary_.journal_reseeds = s.journal_reseeds;
  summary_.latency = summarizeLatency(latencies_ms_);
  summary_.transport = summarizeLatency(transport_ms_);
}

bool StreamingCore::writeEstimate(const std::string& path, TrajectoryFormat format) const {
  if (running_) throw std::logic_error("serve: writeEstimate() while running");
  if (!engine_) return false;
  engine_->writeEstimate(path, format);
  return true;
}

void StreamingCore::refuse(MeasurementKind kind, const std::string& reason, const std::string& key,
                           const std::string& line) {
  {
    std::lock_guard<std::mutex> lock(intake_mutex_);
    intake_.refuse(kind, reason);
  }
  logLimited(key, line);
}

void StreamingCore::refuseControl(const std::string& reason, const std::string& detail) {
  {
    std::lock_guard<std::mutex> lock(intake_mutex_);
    ++control_refused_[reason];
  }
  logLimited("control " + reason, "command refused: " + detail);
}

StreamingCore::Queued StreamingCore::queued(IntakeResult accepted,
                                            std::chrono::steady_clock::time_point received) {
  Queued q;
  q.is_prior = accepted.is_prior;
  q.is_command = accepted.is_command;
  q.sender = accepted.sender;
  q.seq = accepted.seq;
  q.received = received;
  const auto utime = [](const auto& m) { return m.utime; };
  const std::int64_t sent = q.is_command ? accepted.command.utime
                            : q.is_prior ? std::visit(utime, accepted.prior)
                                         : std::visit(utime, accepted.edge);
  q.transport_ms = (nowMicros() - sent) / 1e3 - msSince(received);  // send → arrival
  q.edge = std::move(accepted.edge);
  q.prior = std::move(accepted.prior);
  q.command = accepted.command;
  return q;
}

void StreamingCore::logIntakeNotes(const IntakeResult& r, const char* what) {
  if (r.evicted != 0) {
    logLimited(std::string("evicted ") + what,
               std::string(what) + " sender table full (--max-senders " +
                   std::to_string(intake_.maxSenders()) + "): sender " + std::to_string(r.evicted) +
                   ", heard from least recently, forgotten for sender " + std::to_string(r.sender));
  }
  if (r.dropped > 0) {
    logLimited(std::string("unconfirmed jump ") + what,
               "dropped " + std::to_string(r.dropped) + " held " + what +
                   " message(s) whose seq jump was not confirmed (at sender " +
                   std::to_string(r.sender) + " seq " + std::to_string(r.seq) + ")");
  }
}

void StreamingCore::receive(const Arrival& arrival) {
  const auto received = std::chrono::steady_clock::now();
  const bool prior = arrival.kind == MeasurementKind::kPrior;
  const bool command = arrival.kind == MeasurementKind::kCommand;
  const char* what = nameOf(arrival.kind);
  std::lock_guard<std::mutex> lock(intake_mutex_);
  std::size_t waiting = 0;
  {
    std::lock_guard<std::mutex> queue_lock(queue_mutex_);
    waiting = queue_.size();
  }
  if (waiting >= options_.max_backlog) {
    // Dropped unread: nothing of it is journaled or remembered, so its seq is a gap.
    ++backlog_dropped_;
    logLimited(std::string("backlog ") + what,
               std::string("dropped ") + what + ": " + std::to_string(waiting) +
                   " measurements are waiting for the smoother (the receive backlog's limit)");
    return;
  }
  IntakeResult r = intake_.admit(arrival);
  logIntakeNotes(r, what);
  if (r.evicted != 0 && !command) commit(gaps_.forget(arrival.kind, r.evicted), received);
  if (r.verdict != Intake::kAccepted && r.seq != 0 && !command)
    gaps_.heard(arrival.kind, r.sender, received);  // a resent duplicate is acknowledged too
  if (r.verdict == Intake::kRejected || r.verdict == Intake::kHeld) {
    const std::string key = command ? "command " + r.reason
                            : prior ? "prior " + r.reason
                                    : r.reason;
    std::ostringstream os;
    os << (r.verdict == Intake::kHeld ? "held " : "rejected ") << what;
    if (r.seq != 0) os << " (sender " << r.sender << " seq " << r.seq << ")";
    os << ": " << r.reason << ": " << r.detail;
    logLimited(key, os.str());
    return;
  }
  if (r.verdict == Intake::kDuplicate) return;
  if (r.skipped > 0) {
    logLimited(std::string("gap ") + what,
               std::string("gap: sender ") + std::to_string(r.sender) + " skipped " +
                   std::to_string(r.skipped) + " " + what + " seq numbers before " +
                   std::to_string(r.seq) + (gaps_.on() && !command ? ": asked again" : ""));
  }
  // A confirmed jump: the held messages first, in the order received, then this one.
  std::vector<IntakeResult> accepted = std::move(r.released);
  r.released.clear();
  if (r.wire.empty() && arrival.wire != nullptr && arrival.wire_size > 0) {
    const auto* bytes = static_cast<const unsigned char*>(arrival.wire);
    r.wire.assign(bytes, bytes + arrival.wire_size);  // journaled as received, even if held
  }
  r.arrived = received;
  accepted.push_back(std::move(r));
  if (command || !gaps_.on()) {
    commit(std::move(accepted), received);
    return;
  }
  // Loss recovery: released in seq order, each once; what follows a gap waits for it.
  std::vector<IntakeResult> released;
  std::int64_t given_up = 0;
  for (IntakeResult& a : accepted) {
    std::vector<IntakeResult> now = gaps_.offer(std::move(a), received, &given_up);
    released.insert(released.end(), std::make_move_iterator(now.begin()),
                    std::make_move_iterator(now.end()));
  }
  if (given_up > 0) {
    logGivenUp(given_up, std::string("more than --reorder-limit ") +
                             std::to_string(options_.reorder_limit) + " " + what +
                             "s of one sender held, or below the intake window");
  }
  commit(std::move(released), received);
}

void StreamingCore::commit(std::vector<IntakeResult> accepted,
                           std::chrono::steady_clock::time_point received) {
  if (accepted.empty()) return;
  // Journal before it can be applied: an accepted edge, prior or edge command is never lost.
  // All go into the one journal in the order released, which is the order they are queued in.
  for (auto it = accepted.begin(); journal_ && it != accepted.end();) {
    Arrival a;
    a.kind = it->is_command ? MeasurementKind::kCommand
             : it->is_prior ? MeasurementKind::kPrior
                            : MeasurementKind::kEdge;
    a.edge = it->edge;
    a.prior = it->prior;
    a.command = it->command;
    a.fingerprint = it->fingerprint;
    a.wire = it->wire.empty() ? nullptr : it->wire.data();
    a.wire_size = static_cast<int>(it->wire.size());
    try {
      journal_->appendMeasurement(a);
      ++it;
    } catch (const std::exception& e) {
      // Write-ahead: what the journal does not hold is never applied. The sender may send it
      // again under the same seq once there is room.
      const char* what = nameOf(a.kind);
      intake_.revoke(*it, "journal");
      ++journal_refused_;
      logLimited(std::string("journal ") + what,
                 std::string(what) + " (sender " + std::to_string(it->sender) + " seq " +
                     std::to_string(it->seq) +
                     ") refused, the journal cannot take it: " + e.what());
      it = accepted.erase(it);
    }
  }
  if (accepted.empty()) return;
  {
    // Under the intake's lock (taken by the caller): the queue's order is the journal's.
    std::lock_guard<std::mutex> lock(queue_mutex_);
    for (IntakeResult& r : accepted) {
      r.wire.clear();
      r.wire.shrink_to_fit();
      // Latency from its arrival, also when it waited for a gap.
      const auto arrived =
          r.arrived == std::chrono::steady_clock::time_point{} ? received : r.arrived;
      queue_.push_back(queued(std::move(r), arrived));
    }
  }
  queue_cv_.notify_one();
}

void StreamingCore::logGivenUp(std::int64_t seqs, const std::string& why) {
  logLimited("gap given up", "gave up " + std::to_string(seqs) + " missing seq number(s) (" + why +
                                 "); they stay counted in gaps, a late arrival is still applied");
}

void StreamingCore::windowAnswer(MeasurementKind kind, std::int64_t sender, std::int64_t settled) {
  if (kind == MeasurementKind::kCommand) return;
  std::lock_guard<std::mutex> lock(intake_mutex_);
  std::int64_t given_up = 0;
  std::vector<IntakeResult> released = gaps_.giveUpTo(kind, sender, settled, &given_up);
  if (given_up > 0) {
    logGivenUp(given_up, "sender " + std::to_string(sender) + " holds no " + nameOf(kind) +
                             " at or below seq " + std::to_string(settled) + " any more");
  }
  commit(std::move(released), std::chrono::steady_clock::now());
}

void StreamingCore::recoverLosses() {
  if (!gaps_.on()) return;
  const auto now = std::chrono::steady_clock::now();
  std::vector<ResendRequest> requests;
  {
    std::lock_guard<std::mutex> lock(intake_mutex_);
    std::int64_t given_up = 0;
    std::vector<IntakeResult> released = gaps_.expire(now, &given_up);
    if (given_up > 0) {
      logGivenUp(given_up, "not resent within --gap-hold " +
                               std::to_string(options_.gap_hold.count() / 1e3) + " s");
    }
    commit(std::move(released), now);
    if (now - last_requests_ >= options_.resend_period) {
      requests = gaps_.requests();
      last_requests_ = now;
    }
  }
  std::lock_guard<std::mutex> lock(publish_mutex_);
  for (const ResendRequest& q : requests) publisher_.publishResend(q);
}

void StreamingCore::command(const ControlCommand& c) {
  bool full = false;
  {
    std::lock_guard<std::mutex> lock(queue_mutex_);
    full = commands_.size() >= options_.max_queued_commands;
    if (!full) commands_.push_back(c);
  }
  if (full) {
    refuseControl("queue full", std::to_string(options_.max_queued_commands) +
                                    " commands are already waiting for the smoother");
    return;
  }
  queue_cv_.notify_one();
}

void StreamingCore::ensureEngine(int dim) {
  if (engine_) return;
  engine_ = makeEngine(dim, options_.smoother, options_.batch, options_.robust);
  std::lock_guard<std::mutex> lock(state_mutex_);
  state_.inlier_threshold = engine_->inlierThreshold();
}

void StreamingCore::smootherLoop() {
  for (;;) {
    std::vector<Queued> batch;
    std::vector<ControlCommand> commands;
    bool stopping = false;
    {
      std::unique_lock<std::mutex> lock(queue_mutex_);
      // A held update (its mark did not fit the journal) is tried again at hold_until_.
      const auto ready = [&] {
        return (!queue_.empty() && std::chrono::steady_clock::now() >= hold_until_) ||
               !commands_.empty() || smoother_stop_;
      };
      queue_cv_.wait_for(lock, std::chrono::milliseconds(100), ready);
      if (std::chrono::steady_clock::now() >= hold_until_ || smoother_stop_) batch.swap(queue_);
      commands.swap(commands_);
      stopping = smoother_stop_;
    }
    try {
      if (!batch.empty() && !applyBatch(batch, false)) {
        std::lock_guard<std::mutex> lock(queue_mutex_);
        queue_.insert(queue_.begin(), std::make_move_iterator(batch.begin()),
                      std::make_move_iterator(batch.end()));
        hold_until_ = std::chrono::steady_clock::now() + std::chrono::milliseconds(200);
        held_ = static_cast<std::int64_t>(queue_.size());
        if (stopping) {
          logLine(std::to_string(queue_.size()) +
                  " measurements are in the journal but not applied: the journal could not take "
                  "their update mark; a restart from the journal applies them");
          return;
        }
      } else if (!batch.empty()) {
        std::lock_guard<std::mutex> lock(queue_mutex_);
        held_ = 0;
      }
      for (const auto& c : commands) handleCommand(c);
      recoverLosses();
      solveDeferredWhileIdle();
      pollBatch(false, true);  // a background batch that finished while idle
      if (std::chrono::duration<double>(std::chrono::steady_clock::now() - last_status_).count() >=
          options_.status_period_s) {
        publishStatus();
      }
      if (journal_) journal_->syncIfDue();
    } catch (const std::exception& e) {
      logLine(std::string("error: ") + e.what());
    }
    if (stopping) {
      std::lock_guard<std::mutex> lock(queue_mutex_);
      if (queue_.empty() && commands_.empty()) return;
    }
  }
}

void StreamingCore::solveDeferredWhileIdle() {
  const double budget = options_.smoother.solve_budget_mb;
  if (!engine_ || budget <= 0) return;
  bool solved = false;
  while (engine_->cliquesDeferred() > 0) {
    {
      std::lock_guard<std::mutex> lock(queue_mutex_);
      if (!queue_.empty() || !commands_.empty() || smoother_stop_) break;
    }
    engine_->solveDeferred(budget);
    solved = true;
  }
  if (solved) publishEstimate(false);
}

bool StreamingCore::journalUpdate(int n) {
  if (!journal_) return true;
  try {
    journal_->appendMark(JournalEntry::Type::kUpdateMark, n, state_.updates);
  } catch (const std::exception& e) {
    logLimited("journal mark", "update of " + std::to_string(n) +
                                   " held: the journal cannot take its mark (" + e.what() +
                                   "); retried until it can");
    return false;
  }
  // Group commit: every edge and prior of the batch is on disk before any of it is applied. The
  // mark is in the file either way, so a failed fsync does not hold the update (that would
  // write a second mark); it is logged.
  if (options_.fsync_before_update) {
    try {
      journal_->sync();
    } catch (const std::exception& e) {
      logLimited("journal fsync", std::string("journal: ") + e.what());
    }
  }
  return true;
}

bool StreamingCore::applyBatch(std::vector<Queued>& batch, bool from_journal) {
  // The stream's dimension comes with its first edge or prior (a command has none).
  for (const Queued& q : batch) {
    if (q.is_command) continue;
    ensureEngine(q.is_prior ? dimOf(q.prior) : (q.edge.index() == 0 ? 2 : 3));
    break;
  }
  if (!from_journal && !journalUpdate(static_cast<int>(batch.size()))) return false;
  // In the order received (and journaled): edges and priors interleaved as they came.
  std::int64_t edges = 0, rejected = 0, duplicates = 0, priors_rejected = 0, commands = 0;
  const Queued* last_edge = nullptr;
  for (const auto& q : batch) {
    if (q.is_command) {
      applyEdgeCommand(q, from_journal);
      ++commands;
      continue;
    }
    const EdgeResult r = q.is_prior ? engine_->addPrior(q.prior) : engine_->add(q.edge);
    if (!q.is_prior) {
      ++edges;
      last_edge = &q;
    }
    if (r.status == EdgeStatus::kRejected) {
      ++(q.is_prior ? priors_rejected : rejected);
      if (!from_journal) {
        const std::string what = q.is_prior ? "prior" : "edge";
        logLimited("smoother refused " + what, "smoother refused " + what + " (sender " +
                                                   std::to_string(q.sender) + " seq " +
                                                   std::to_string(q.seq) + "): " + r.reason);
      }
    } else if (r.status == EdgeStatus::kDuplicate) {
      ++duplicates;
    }
  }
  const std::int64_t priors = static_cast<std::int64_t>(batch.size()) - edges - commands;
  if (!engine_) {  // only commands, before any pose: each was refused as naming no known pose
    if (from_journal) {
      std::lock_guard<std::mutex> lock(state_mutex_);
      state_.journal_commands += commands;
    } else {
      publishStatus();
    }
    return true;
  }
  try {
    engine_->update();
  } catch (const std::exception& e) {
    logLine(std::string("update failed: ") + e.what());
  }
  const OnlineStats stats = engine_->stats();
  {
    std::lock_guard<std::mutex> lock(state_mutex_);
    state_.applied += edges;
    state_.priors_applied += priors;
    ++state_.updates;
    state_.poses = stats.poses;
    state_.pending = stats.edges_pending;
    state_.components = stats.components;
    state_.edges_disabled = stats.edges_disabled;
    state_.pairs_disabled = stats.pairs_disabled;
    state_.robust_stats = stats;
    state_.smoother_rejected += rejected;
    state_.smoother_duplicates += duplicates;
    state_.smoother_priors_rejected += priors_rejected;
    if (last_edge != nullptr) {
      state_.last_sender = last_edge->sender;
      state_.last_seq = last_edge->seq;
    }
    if (from_journal) {
      state_.journal_edges += edges;
      state_.journal_priors += priors;
      state_.journal_commands += commands;
      ++state_.journal_updates;
    }
  }
  if (from_journal) return true;  // reseeds come from the journal's own records
  engine_->noteUpdate();
  pollBatch(false, false);  // a finished batch's reseed goes into this update's estimate
  const bool full = options_.full_every == 1 ||
                    (options_.full_every > 1 && state_.updates % options_.full_every == 0);
  publishEstimate(full);
  if (commands > 0) publishStatus();  // the command's result, for a sender waiting on it
  {
    std::lock_guard<std::mutex> lock(state_mutex_);
    for (const auto& q : batch) {
      latencies_ms_.push_back(msSince(q.received));
      transport_ms_.push_back(q.transport_ms);
    }
  }
  const int every = options_.batch.every;
  if (every > 0 && state_.updates % every == 0) startBatch(false);
  return true;
}

void StreamingCore::applyEdgeCommand(const Queued& q, bool from_journal) {
  const StreamEdgeCommand& c = q.command;
  EdgeSwitchResult r;
  if (engine_) {
    r = engine_->command(c);
  } else {
    r.status = EdgeSwitchStatus::kUnknownPose;
    r.reason = std::string(toString(c.kind)) + " edge " + std::to_string(c.from) + " - " +
               std::to_string(c.to) + ": no pose is known yet";
  }
  if (!from_journal) {
    // A sender provokes these lines at will (commands naming no known pose, toggles): limited.
    logLimited(std::string("edge command ") + toString(r.status),
               "edge command (sender " + std::to_string(q.sender) + " seq " +
                   std::to_string(q.seq) + "): " + (r.applied() ? "" : "refused: ") + r.reason);
  }
  std::lock_guard<std::mutex> lock(state_mutex_);
  ++state_.commands_applied;
  if (!r.applied()) {
    ++state_.commands_refused;
    ++state_.command_refusals[toString(r.status)];
  }
  state_.last_command_sender = q.sender;
  state_.last_command_seq = q.seq;
  state_.last_command_result = (r.applied() ? "" : std::string("refused: ")) + r.reason;
}

void StreamingCore::startBatch(bool on_command) {
  if (!engine_) {
    if (on_command) logLimited("batch refused", "batch: no estimate yet");
    return;
  }
  const bool busy = engine_->batchInFlight();
  bool started = false;
  try {
    started = engine_->startBatch(state_.updates);
  } catch (const std::exception& e) {
    logLine(std::string("batch could not start: ") + e.what());
  }
  {
    std::lock_guard<std::mutex> lock(state_mutex_);
    state_.batches_skipped = engine_->batchesSkipped();
  }
  if (!started) {
    if (on_command)
      logLimited("batch refused",
                 busy ? "batch: one is still running" : "batch: too few poses yet");
    return;
  }
  if (options_.batch.synchronous) pollBatch(true, true);
}

bool StreamingCore::pollBatch(bool wait, bool publish) {
  if (!engine_ || !engine_->batchInFlight()) return false;
  Estimate seed;
  std::optional<refine::BatchRun> run;
  try {
    run = engine_->collectBatch(wait, &seed);
  } catch (const std::exception& e) {
    logLine(std::string("batch failed: ") + e.what());
    return false;
  }
  if (!run) return false;
  if (seed.num_poses > 0) applyReseed(seed, false, &*run);
  {
    std::ostringstream os;
    os << "batch " << refine::toString(options_.batch.solver) << " of update " << run->update
       << ": " << run->poses << " poses, F incremental " << run->F_incremental << " batch "
       << run->F_batch << ", " << run->winner << " wins by " << run->margin << " (" << run->time_s
       << " s, " << run->updates_during << " updates meanwhile)"
       << (run->reseeded ? ", reseeded" : "") << (run->cancelled ? ", cancelled" : "");
    logLine(os.str());
  }
  {
    std::lock_guard<std::mutex> lock(state_mutex_);
    batch_runs_.push_back(*run);
  }
  if (run->reseeded && publish) publishEstimate(options_.full_every == 1);
  publishStatus();
  return true;
}

void StreamingCore::applyReseed(const Estimate& seed, bool from_journal, refine::BatchRun* run) {
  if (!from_journal && journal_) {
    // Journaled before it is applied: a restart applies the same values at the same point.
    Estimate record = seed;
    record.utime = nowMicros();
    record.update = state_.updates;
    try {
      journal_->appendReseed(record);
    } catch (const std::exception& e) {
      logLine(std::string("reseed skipped, the journal cannot take it: ") + e.what());
      return;
    }
  }
  ReseedResult r;
  try {
    r = engine_->reseed(seed);  // kept only if it lowers F: the same decision on replay
  } catch (const std::exception& e) {
    logLine(std::string("reseed failed: ") + e.what());
    return;
  }
  std::lock_guard<std::mutex> lock(state_mutex_);
  if (r.applied) {
    ++state_.reseeds;
    if (from_journal) ++state_.journal_reseeds;
    state_.F = r.F_rebuilt;
  }
  if (run) {
    run->reseeded = r.applied;
    run->reseed_rejected = !r.applied;
    run->reseed_s = r.stats.time_s;
    run->F_before_reseed = r.F_before;
    run->F_after_reseed = r.F_rebuilt;
    run->reseed_update = state_.updates;
  }
}

void StreamingCore::refine(bool from_journal, int cut) {
  if (!engine_) return;
  if (!from_journal) {
    try {
      if (journal_) journal_->appendMark(JournalEntry::Type::kRefineMark, 0, state_.updates);
    } catch (const std::exception& e) {
      // Unjournaled, a refinement would make the journal's estimate differ from ours.
      logLine(std::string("refinement skipped: the journal cannot take its mark (") + e.what() +
              ")");
      return;
    }
  }
  CancellationToken replayed_cut;  // a journaled exit refinement cut after cut − 1 checks
  if (cut > 0) replayed_cut.cancelAfterChecks(cut - 1);
  runRefinement(cut > 0 ? &replayed_cut : nullptr);
}

StreamingCore::Refinement StreamingCore::runRefinement(const CancellationToken* cancel) {
  Refinement r;
  const auto t0 = std::chrono::steady_clock::now();
  r.F_before = engine_->objective();
  try {
    r.stats = engine_->refine(cancel);
  } catch (const std::exception& e) {
    logLine(std::string("refinement failed: ") + e.what());
  }
  r.F_after = engine_->objective();
  r.seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
  std::lock_guard<std::mutex> lock(state_mutex_);
  ++state_.refinements;
  state_.refine_F_before = r.F_before;
  state_.refine_F_after = r.F_after;
  state_.refine_time_s = r.seconds;
  state_.F = r.F_after;
  return r;
}

// The exit refinement runs first and is journaled after, with how it ended: to convergence
// (mark 0), or cut by its budget or cancelExit() after k passed checks (mark k + 1), so that a
// restart repeats exactly this refinement. A watchdog thread cancels the token at the budget.
void StreamingCore::refineOnExit() {
  const CancellationToken& cancel = options_.exit_refine_cancel;
  std::mutex watch_mutex;
  std::condition_variable watch_cv;
  bool done = false;
  std::thread watchdog;
  const double budget = options_.exit_refine_budget_s;
  if (std::isfinite(budget)) {
    watchdog = std::thread([&] {
      std::unique_lock<std::mutex> lock(watch_mutex);
      const auto limit = std::chrono::duration<double>(budget);
      if (!watch_cv.wait_for(lock, limit, [&] { return done; })) cancel.cancel();
    });
  }
  const Refinement r = runRefinement(&cancel);
  {
    std::lock_guard<std::mutex> lock(watch_mutex);
    done = true;
  }
  watch_cv.notify_all();
  if (watchdog.joinable()) watchdog.join();
  const UpdateStats& st = r.stats;
  if (st.cancelled) {
    std::ostringstream line;
    line << "exit refinement cut after " << st.refine_iterations << " iteration"
         << (st.refine_iterations == 1 ? "" : "s") << " and " << r.seconds << " s (F " << r.F_before
         << " -> " << r.F_after << "; --exit-refine-budget " << budget << " s)";
    logLine(line.str());
  }
  if (journal_) {
    try {
      journal_->appendMark(JournalEntry::Type::kRefineMark,
                           st.cancelled ? cancel.checksPassed() + 1 : 0, state_.updates);
    } catch (const std::exception& e) {
      logLine(std::string("journal: the exit refinement's mark was not written (") + e.what() +
              "); a restart starts from the estimate before it");
    }
  }
  std::lock_guard<std::mutex> lock(state_mutex_);
  exit_refine_ = {st.refine_iterations, st.cancelled, r.seconds};
}

void StreamingCore::writeSnapshot(const ControlCommand& c) {
  if (!snapshots_.enabled()) {
    refuseControl("snapshot no dir",
                  "SNAPSHOT " + SnapshotDir::printable(c.path) +
                      ": no --snapshot-dir, so nothing on the bus may write a file");
    return;
  }
  if (std::string problem = SnapshotDir::checkName(c.path); !problem.empty()) {
    refuseControl("snapshot name", "SNAPSHOT: " + problem);
    return;
  }
  if (!engine_) {
    logLimited("snapshot refused", "snapshot: no estimate yet");
    return;
  }
  const std::string problem =
      snapshots_.write(c.path, [this](const std::string& path) { engine_->writeG2o(path); });
  if (!problem.empty()) {
    refuseControl("snapshot refused",
                  "SNAPSHOT " + SnapshotDir::printable(c.path) + ": " + problem);
    return;
  }
  logLine("snapshot written to " + snapshots_.dir() + "/" + c.path);
}

void StreamingCore::writeClosures(const ControlCommand& c) {
  // Through SNAPSHOT's rules: a plain name inside the operator's --snapshot-dir, nowhere else.
  if (!snapshots_.enabled()) {
    refuseControl("closures no dir",
                  "CLOSURES " + SnapshotDir::printable(c.path) +
                      ": no --snapshot-dir, so nothing on the bus may write a file");
    return;
  }
  if (std::string problem = SnapshotDir::checkName(c.path); !problem.empty()) {
    refuseControl("closures name", "CLOSURES: " + problem);
    return;
  }
  if (!options_.robust) {
    logLimited("closures refused", "closures: no report without --robust");
    return;
  }
  if (!engine_) {
    logLimited("closures refused", "closures: no estimate yet");
    return;
  }
  const std::vector<ClosureReport> closures = engine_->closures();
  const std::string problem = snapshots_.write(
      c.path, [&closures](const std::string& path) { writeClosureReport(path, closures); });
  if (!problem.empty()) {
    refuseControl("closures refused",
                  "CLOSURES " + SnapshotDir::printable(c.path) + ": " + problem);
    return;
  }
  logLine("closures: " + std::to_string(closures.size()) + " written to " + snapshots_.dir() + "/" +
          c.path);
}

void StreamingCore::handleCommand(const ControlCommand& c) {
  switch (c.kind) {
    case ControlCommand::Kind::kRefine:
      refine(false);
      publishEstimate(true);
      publishStatus();
      break;
    case ControlCommand::Kind::kPublishFull:
      publishEstimate(true);
      break;
    case ControlCommand::Kind::kSnapshot:
      writeSnapshot(c);
      break;
    case ControlCommand::Kind::kStatus:
      publishStatus();
      break;
    case ControlCommand::Kind::kBatch:
      startBatch(true);
      break;
    case ControlCommand::Kind::kClosures:
      writeClosures(c);
      break;
    case ControlCommand::Kind::kCovariance:
      publishCovariance(c);
      break;
    case ControlCommand::Kind::kUnknown:
      logLimited("unknown command", "unknown command " + std::to_string(c.code));
  }
}

void StreamingCore::publishCovariance(const ControlCommand& c) {
  CovarianceAnswer a;
  a.request = c.utime;
  {
    std::lock_guard<std::mutex> lock(state_mutex_);
    a.update = state_.updates;
  }
  try {
    if (!c.ids_problem.empty()) throw std::invalid_argument(c.ids_problem);
    a.ids = c.ids;
    if (!engine_) throw std::runtime_error("no estimate yet");
    a.matrix = engine_->covariance(a.ids);
  } catch (const std::exception& e) {  // bad ids, an unknown id, a pose not updated yet
    a.matrix.resize(0, 0);
    a.error = e.what();
    logLimited("covariance refused", "covariance refused: " + a.error);
  }
  std::lock_guard<std::mutex> lock(publish_mutex_);
  publisher_.publishCovariance(a);
}

void StreamingCore::publishEstimate(bool full) {
  if (!engine_) return;
  // What was published while the link was down is lost: the first estimate after it is full.
  if (publisher_.takeRecovered()) full = true;
  Estimate m = engine_->estimate(full);
  m.utime = nowMicros();
  {
    std::lock_guard<std::mutex> lock(state_mutex_);
    m.last_sender = state_.last_sender;
    m.last_seq = state_.last_seq;
    m.update = state_.updates;
    if (full) state_.F = m.F;
  }
  std::lock_guard<std::mutex> lock(publish_mutex_);
  publisher_.publishEstimate(m);
}

CoreStatus StreamingCore::status() const {
  CoreStatus s;
  {
    std::lock_guard<std::mutex> lock(state_mutex_);
    s = state_;
    s.batches = static_cast<int>(batch_runs_.size());
    if (!batch_runs_.empty()) s.last_batch = batch_runs_.back();
    const size_t n = latencies_ms_.size();
    const size_t window = std::min(n, static_cast<size_t>(std::max(1, options_.latency_window)));
    s.latency = summarizeLatency(std::vector<double>(
        latencies_ms_.end() - static_cast<std::ptrdiff_t>(window), latencies_ms_.end()));
    s.latency_window = static_cast<int>(window);
  }
  s.utime = nowMicros();
  {
    std::lock_guard<std::mutex> lock(intake_mutex_);
    s.edges = intake_.counts();
    s.priors = intake_.priorCounts();
    s.commands = intake_.commandCounts();
    s.control_refused = control_refused_;
    s.journal_refused = journal_refused_;
    s.backlog_dropped = backlog_dropped_;
    s.edge_senders = static_cast<std::int64_t>(intake_.senders(MeasurementKind::kEdge));
    s.edge_gaps_by_sender = intake_.gapsBySender(MeasurementKind::kEdge);
    s.loss = gaps_.counts();
  }
  s.held = held_;
  if (journal_) s.journal_bytes = journal_->bytes();
  s.transport = publisher_.transportState();
  return s;
}

void StreamingCore::publishStatus() {
  if (engine_) {
    const double F = engine_->objective();
    std::lock_guard<std::mutex> lock(state_mutex_);
    state_.F = F;
  }
  const CoreStatus s = status();
  last_status_ = std::chrono::steady_clock::now();
  std::lock_guard<std::mutex> lock(publish_mutex_);
  publisher_.publishStatus(s);
}

void StreamingCore::replayJournal() {
  std::deque<Queued> unmarked;
  const auto now = std::chrono::steady_clock::now();
  // In file order: measurements re-enter the intake and the queue in the order they were
  // received, and each mark takes the next N of them, whichever kind.
  const auto entry = [&](JournalEntry&& e) {
    switch (e.type) {
      case JournalEntry::Type::kMeasurement: {
        // The same rules as live: a seq jump is held until confirmed (a live run journals a
        // jump's messages together once confirmed, so the replay confirms them alike).
        IntakeResult r = intake_.admit(e.arrival);
        logIntakeNotes(r, nameOf(e.arrival.kind));
        if (r.verdict == Intake::kHeld) return;
        if (r.verdict != Intake::kAccepted) {
          logLine(std::string("journal: ") + nameOf(e.arrival.kind) + " (sender " +
                  std::to_string(r.sender) + " seq " + std::to_string(r.seq) +
                  ") skipped on replay: " + r.reason);
          return;
        }
        for (IntakeResult& released : r.released)
          unmarked.push_back(queued(std::move(released), now));
        r.released.clear();
        unmarked.push_back(queued(std::move(r), now));
        return;
      }
      case JournalEntry::Type::kUpdateMark: {
        const size_t n =
            std::min(unmarked.size(), static_cast<size_t>(std::max(0, e.measurements)));
        if (n == 0) return;
        std::vector<Queued> batch(std::make_move_iterator(unmarked.begin()),
                                  std::make_move_iterator(unmarked.begin() + n));
        unmarked.erase(unmarked.begin(), unmarked.begin() + n);
        applyBatch(batch, true);
        return;
      }
      case JournalEntry::Type::kRefineMark:
        refine(true, e.measurements);
        return;
      case JournalEntry::Type::kReseed:
        if (!engine_) {
          logLine("journal: a reseed record could not be used; skipped");
          return;
        }
        applyReseed(e.seed, true, nullptr);
        return;
      case JournalEntry::Type::kUnreadable:
        logLine("journal: " + e.problem + "; skipped");
        return;
    }
  };
  bool any = false;
  journal_->replay(
      [&](JournalEntry&& e) {
        any = true;
        entry(std::move(e));
      },
      [this](const std::string& note) { logLine(note); });
  // Accepted but not yet applied when the journal ended: the first update takes them.
  queue_.assign(std::make_move_iterator(unmarked.begin()), std::make_move_iterator(unmarked.end()));
  if (any) {
    logLine("journal " + journal_->name() + ": replayed " + std::to_string(state_.journal_edges) +
            " edges, " + std::to_string(state_.journal_priors) + " priors and " +
            std::to_string(state_.journal_commands) + " edge commands in " +
            std::to_string(state_.journal_updates) + " updates; " + std::to_string(queue_.size()) +
            " to apply");
  }
}

}  // namespace arbor::serve
