#include "arbor/tools/serve/serve_service.h"

#include "arbor/tools/serve/closure_report.h"
#include "arbor/tools/serve/lcm_tuning.h"

#include <algorithm>
#include <cmath>
#include <deque>
#include <optional>
#include <sstream>
#include <stdexcept>

namespace arbor::serve {
namespace {

constexpr const char* kMarkChannel = "ARBOR_JOURNAL_MARK";
constexpr const char* kReseedChannel = "ARBOR_JOURNAL_RESEED";

double msSince(std::chrono::steady_clock::time_point t) {
  return std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - t).count();
}

std::int64_t leadingHash(const std::vector<std::uint8_t>& data) {
  std::int64_t h = 0;
  for (size_t k = 0; k < 8 && k < data.size(); ++k) h = (h << 8) | data[k];
  return data.size() < 8 ? 0 : h;
}

}  // namespace

std::int64_t nowMicros() {
  return std::chrono::duration_cast<std::chrono::microseconds>(
             std::chrono::system_clock::now().time_since_epoch())
      .count();
}

Channels Channels::withPrefix(const std::string& prefix) {
  return {prefix + "ARBOR_EDGES",      prefix + "ARBOR_ESTIMATE",  prefix + "ARBOR_STATUS",
          prefix + "ARBOR_COMMAND",    prefix + "ARBOR_PRIORS",    prefix + "ARBOR_EDGE_COMMANDS",
          prefix + "ARBOR_LINK_PROBE", prefix + "ARBOR_COVARIANCE"};
}

Service::Service(lcm::LCM& lcm, ServeOptions options) : Service(lcm, lcm, std::move(options)) {}

Service::Service(lcm::LCM& receive, lcm::LCM& publish, ServeOptions options)
    : Service(nullptr, nullptr, std::move(options)) {
  LinkWatchOptions r;
  r.name = "receive link";
  r.probe_channel = channels_.link_probe;
  r.log = [this](const std::string& line) { logLine(line); };
  LinkWatchOptions p = r;
  p.name = "publish link";
  p.probe_channel.clear();
  owned_receive_ = std::make_unique<LinkWatch>(receive, r);
  owned_publish_ = std::make_unique<LinkWatch>(publish, p);
  receive_ = owned_receive_.get();
  publish_ = owned_publish_.get();
}

Service::Service(LinkWatch& receive, LinkWatch& publish, ServeOptions options)
    : Service(&receive, &publish, std::move(options)) {}

Service::Service(LinkWatch* receive, LinkWatch* publish, ServeOptions options)
    : receive_(receive),
      publish_(publish),
      options_(std::move(options)),
      channels_(Channels::withPrefix(options_.channel_prefix)),
      snapshots_(options_.snapshot_dir),
      limiter_(options_.log_period),
      intake_(options_.dim, options_.intake_window, options_.max_senders) {
  options_.batch.cancel = CancellationToken();  // the service's own: stop() cancels it
  if (options_.dim != 0 && options_.dim != 2 && options_.dim != 3) {
    throw std::invalid_argument("serve: dim " + std::to_string(options_.dim) + " is not 2 or 3");
  }
  if (options_.batch.every < 0) {
    throw std::invalid_argument("serve: batch every " + std::to_string(options_.batch.every) +
                                " updates is < 0");
  }
}

Service::~Service() {
  if (running_) {
    try {
      stop();
    } catch (...) {
    }
  }
}

void Service::logLine(const std::string& line) {
  if (options_.log == nullptr) return;
  std::lock_guard<std::mutex> lock(log_mutex_);
  *options_.log << "arbor serve: " << line << std::endl;
}

void Service::logLimited(const std::string& key, const std::string& line) {
  std::int64_t suppressed = 0;
  if (limiter_.allow(key, &suppressed)) logLine(LogLimiter::withSuppressed(line, suppressed));
}

void Service::start() {
  if (running_) throw std::logic_error("serve: start() twice");
  if (!options_.journal_path.empty()) replayJournal();
  if (engine_) publishEstimate(true);
  last_status_ = std::chrono::steady_clock::now();
  // Queue capacity 0 at liblcm (LinkWatch): never dropped there, the queue is ours.
  const auto on = [this](void (Service::*handler)(const lcm::ReceiveBuffer*, const std::string&)) {
    return [this, handler](const lcm::ReceiveBuffer* rbuf, const std::string& channel) {
      (this->*handler)(rbuf, channel);
    };
  };
  receive_->subscribe(channels_.edges, on(&Service::onEdge));
  receive_->subscribe(channels_.priors, on(&Service::onPrior));
  receive_->subscribe(channels_.command, on(&Service::onCommand));
  receive_->subscribe(channels_.edge_commands, on(&Service::onEdgeCommand));
  if (options_.udpm_port > 0) {  // the socket exists from the first subscribe on
    const std::int64_t bytes = udpReceiveBufferBytes(options_.udpm_port);
    {
      std::lock_guard<std::mutex> lock(state_mutex_);
      recv_buf_bytes_ = bytes;
    }
    logLine("udpm receive buffer " + std::to_string(bytes) + " bytes (SO_RCVBUF)");
  }
  receive_stop_ = false;
  smoother_stop_ = false;
  smoother_thread_ = std::thread(&Service::smootherLoop, this);
  receive_thread_ = std::thread(&Service::receiveLoop, this);
  running_ = true;
}

void Service::stop() {
  if (!running_) return;
  running_ = false;
  // A background batch (a whole RTR solve) stops at its next iteration; the batches the last
  // update may still start stop at their first. The cancelled run is collected below, without a
  // reseed.
  options_.batch.cancel.cancel();
  receive_stop_ = true;
  receive_thread_.join();
  receive_->unsubscribeAll();
  {
    std::lock_guard<std::mutex> lock(queue_mutex_);
    smoother_stop_ = true;
  }
  queue_cv_.notify_all();
  smoother_thread_.join();

  pollBatch(true, false);  // a batch still running was cancelled: collected, not reseeded
  if (engine_ && options_.refine_on_exit) refine(false);
  if (journal_) {
    try {
      journal_->sync();
    } catch (const std::exception& e) {
      logLine(std::string("journal: ") + e.what());
    }
  }
  summary_ = ServeSummary();
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
    summary_.control_refused = control_refused_;
  }
  summary_.link_outages = receive_->counts().outages + publish_->counts().outages;
  {
    std::lock_guard<std::mutex> lock(queue_mutex_);
    summary_.held_at_stop = static_cast<std::int64_t>(queue_.size());
  }
  std::lock_guard<std::mutex> lock(state_mutex_);
  summary_.applied = applied_;
  summary_.updates = updates_;
  summary_.poses = poses_;
  summary_.pending = pending_;
  summary_.smoother_rejected = smoother_rejected_;
  summary_.smoother_duplicates = smoother_duplicates_;
  summary_.journal_edges = journal_edges_;
  summary_.priors_applied = priors_applied_;
  summary_.smoother_priors_rejected = smoother_priors_rejected_;
  summary_.journal_priors = journal_priors_;
  summary_.components = components_;
  summary_.commands_applied = commands_applied_;
  summary_.commands_refused = commands_refused_;
  summary_.commands_refused_by_reason = command_refusals_;
  summary_.journal_commands = journal_commands_;
  summary_.recv_buf_bytes = std::max(
      recv_buf_bytes_, options_.udpm_port > 0 ? udpReceiveBufferBytes(options_.udpm_port) : 0);
  summary_.edges_disabled = edges_disabled_;
  summary_.pairs_disabled = pairs_disabled_;
  summary_.journal_updates = journal_updates_;
  summary_.refinements = refinements_;
  summary_.batches = batch_runs_;
  summary_.batches_skipped = batches_skipped_;
  summary_.reseeds = reseeds_;
  summary_.journal_reseeds = journal_reseeds_;
  summary_.latency = cli::summarizeLatency(latencies_ms_);
  summary_.transport = cli::summarizeLatency(transport_ms_);
}

bool Service::writeG2o(const std::string& path) const {
  if (running_) throw std::logic_error("serve: writeG2o() while running");
  if (!engine_) return false;
  engine_->writeG2o(path);
  return true;
}

void Service::receiveLoop() {
  // A dead link is noticed, logged and re-created inside handle(); state here is untouched.
  while (!receive_stop_) receive_->handle(50);
}

bool Service::fitsLimit(int size, int limit, const std::string& channel, EdgeIntake::Kind kind) {
  if (size <= limit) return true;
  {
    std::lock_guard<std::mutex> lock(intake_mutex_);
    intake_.refuse(kind, "oversize");
  }
  logLimited("oversize " + channel, "refused a message of " + std::to_string(size) + " bytes on " +
                                        channel + ": over its limit of " + std::to_string(limit) +
                                        " bytes (not decoded)");
  return false;
}

void Service::refuseControl(const std::string& reason, const std::string& detail) {
  {
    std::lock_guard<std::mutex> lock(intake_mutex_);
    ++control_refused_[reason];
  }
  logLimited("control " + reason, "command refused: " + detail);
}

void Service::onEdge(const lcm::ReceiveBuffer* rbuf, const std::string& channel) {
  // Nothing may unwind through liblcm's C frames.
  try {
    if (!fitsLimit(static_cast<int>(rbuf->data_size), options_.message_limits.edge, channel,
                   EdgeIntake::Kind::kEdge)) {
      return;
    }
    receiveMeasurement(rbuf, channel, Incoming::kEdge);
  } catch (const std::exception& e) {
    logLine(std::string("error while receiving an edge: ") + e.what());
  }
}

void Service::onPrior(const lcm::ReceiveBuffer* rbuf, const std::string& channel) {
  try {
    if (!fitsLimit(static_cast<int>(rbuf->data_size), options_.message_limits.prior, channel,
                   EdgeIntake::Kind::kPrior)) {
      return;
    }
    receiveMeasurement(rbuf, channel, Incoming::kPrior);
  } catch (const std::exception& e) {
    logLine(std::string("error while receiving a prior: ") + e.what());
  }
}

void Service::onEdgeCommand(const lcm::ReceiveBuffer* rbuf, const std::string& channel) {
  try {
    if (!fitsLimit(static_cast<int>(rbuf->data_size), options_.message_limits.edge_command, channel,
                   EdgeIntake::Kind::kCommand)) {
      return;
    }
    receiveMeasurement(rbuf, channel, Incoming::kCommand);
  } catch (const std::exception& e) {
    logLine(std::string("error while receiving an edge command: ") + e.what());
  }
}

void Service::onCommand(const lcm::ReceiveBuffer* rbuf, const std::string& channel) {
  try {
    receiveCommand(rbuf, channel);
  } catch (const std::exception& e) {
    logLine(std::string("error while receiving a command: ") + e.what());
  }
}

Service::Queued Service::queued(IntakeResult accepted,
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
  q.transport_ms = (nowMicros() - sent) / 1e3;
  q.edge = std::move(accepted.edge);
  q.prior = std::move(accepted.prior);
  q.command = accepted.command;
  return q;
}

void Service::receiveMeasurement(const lcm::ReceiveBuffer* rbuf, const std::string& channel,
                                 Incoming kind) {
  const auto received = std::chrono::steady_clock::now();
  const bool prior = kind == Incoming::kPrior, command = kind == Incoming::kCommand;
  const char* what = command ? "edge command" : prior ? "prior" : "edge";
  IntakeResult r;
  {
    std::lock_guard<std::mutex> lock(intake_mutex_);
    const int size = static_cast<int>(rbuf->data_size);
    r = command ? intake_.admitCommand(rbuf->data, size)
        : prior ? intake_.admitPrior(rbuf->data, size)
                : intake_.admit(rbuf->data, size);
    if (r.verdict == Intake::kRejected) {
      const std::string key = command ? "command " + r.reason
                              : prior ? "prior " + r.reason
                                      : r.reason;
      std::ostringstream os;
      os << "rejected " << what;
      if (r.seq != 0) os << " (sender " << r.sender << " seq " << r.seq << ")";
      os << ": " << r.reason << ": " << r.detail;
      logLimited(key, os.str());
      return;
    }
    if (r.verdict == Intake::kDuplicate) return;
    if (r.skipped > 0) {
      logLimited(std::string("gap ") + what, std::string("gap: sender ") +
                                                 std::to_string(r.sender) + " skipped " +
                                                 std::to_string(r.skipped) + " " + what +
                                                 " seq numbers before " + std::to_string(r.seq));
    }
    // Journal before it can be applied: an accepted edge, prior or edge command is never lost.
    // All go into the one log in the order received, which is the order they are queued in.
    if (journal_) {
      try {
        journal_->append(channel, nowMicros(), rbuf->data, size);
      } catch (const std::exception& e) {
        // Write-ahead: what the journal does not hold is never applied. The sender may send it
        // again under the same seq once there is room.
        intake_.revoke(r, "journal");
        ++journal_refused_;
        logLimited(std::string("journal ") + what,
                   std::string(what) + " (sender " + std::to_string(r.sender) + " seq " +
                       std::to_string(r.seq) +
                       ") refused, the journal cannot take it: " + e.what());
        return;
      }
    }
  }
  {
    std::lock_guard<std::mutex> lock(queue_mutex_);
    queue_.push_back(queued(std::move(r), received));
  }
  queue_cv_.notify_one();
}

void Service::receiveCommand(const lcm::ReceiveBuffer* rbuf, const std::string& channel) {
  const int size = static_cast<int>(rbuf->data_size);
  if (size > options_.message_limits.command) {
    refuseControl("oversize", "a message of " + std::to_string(size) + " bytes on " + channel +
                                  ": over its limit of " +
                                  std::to_string(options_.message_limits.command) +
                                  " bytes (not decoded)");
    return;
  }
  command_t c;
  std::string detail;
  const MessageProblem p = decodeMessage(rbuf->data, size, &c, &detail);
  if (p != MessageProblem::kNone) {
    refuseControl(toString(p), std::string(toString(p)) + ": " + detail);
    return;
  }
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

void Service::smootherLoop() {
  for (;;) {
    std::vector<Queued> batch;
    std::vector<command_t> commands;
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

void Service::ensureEngine(int dim) {
  if (engine_) return;
  engine_ = makeEngine(dim, options_.smoother, options_.batch, options_.robust);
  std::lock_guard<std::mutex> lock(state_mutex_);
  inlier_threshold_ = engine_->inlierThreshold();
}

void Service::writeMark(std::int8_t kind, int edges) {
  if (!journal_) return;
  journal_mark_t m;
  m.utime = nowMicros();
  m.kind = kind;
  m.edges = edges;
  m.update = updates_;
  const auto bytes = encodeMessage(m);
  journal_->append(kMarkChannel, m.utime, bytes.data(), static_cast<int>(bytes.size()),
                   EventClass::kRecord);
}

bool Service::journalUpdate(int n) {
  if (!journal_) return true;
  try {
    writeMark(journal_mark_t::UPDATE, n);
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

bool Service::applyBatch(std::vector<Queued>& batch, bool from_journal) {
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
        logLine(std::string("smoother refused ") + (q.is_prior ? "prior" : "edge") + " (sender " +
                std::to_string(q.sender) + " seq " + std::to_string(q.seq) + "): " + r.reason);
      }
    } else if (r.status == EdgeStatus::kDuplicate) {
      ++duplicates;
    }
  }
  const std::int64_t priors = static_cast<std::int64_t>(batch.size()) - edges - commands;
  if (!engine_) {  // only commands, before any pose: each was refused as naming no known pose
    if (from_journal) {
      std::lock_guard<std::mutex> lock(state_mutex_);
      journal_commands_ += commands;
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
    applied_ += edges;
    priors_applied_ += priors;
    ++updates_;
    poses_ = stats.poses;
    pending_ = stats.edges_pending;
    components_ = stats.components;
    edges_disabled_ = stats.edges_disabled;
    pairs_disabled_ = stats.pairs_disabled;
    robust_stats_ = stats;
    smoother_rejected_ += rejected;
    smoother_duplicates_ += duplicates;
    smoother_priors_rejected_ += priors_rejected;
    if (last_edge != nullptr) {
      last_sender_ = last_edge->sender;
      last_seq_ = last_edge->seq;
    }
    if (from_journal) {
      journal_edges_ += edges;
      journal_priors_ += priors;
      journal_commands_ += commands;
      ++journal_updates_;
    }
  }
  if (from_journal) return true;  // reseeds come from the journal's own records
  engine_->noteUpdate();
  pollBatch(false, false);  // a finished batch's reseed goes into this update's estimate
  const bool full =
      options_.full_every == 1 || (options_.full_every > 1 && updates_ % options_.full_every == 0);
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
  if (every > 0 && updates_ % every == 0) startBatch(false);
  return true;
}

void Service::applyEdgeCommand(const Queued& q, bool from_journal) {
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
    logLine("edge command (sender " + std::to_string(q.sender) + " seq " + std::to_string(q.seq) +
            "): " + (r.applied() ? "" : "refused: ") + r.reason);
  }
  std::lock_guard<std::mutex> lock(state_mutex_);
  ++commands_applied_;
  if (!r.applied()) {
    ++commands_refused_;
    ++command_refusals_[toString(r.status)];
  }
  last_command_sender_ = q.sender;
  last_command_seq_ = q.seq;
  last_command_result_ = (r.applied() ? "" : std::string("refused: ")) + r.reason;
}

void Service::startBatch(bool on_command) {
  if (!engine_) {
    if (on_command) logLine("batch: no estimate yet");
    return;
  }
  const bool busy = engine_->batchInFlight();
  bool started = false;
  try {
    started = engine_->startBatch(updates_);
  } catch (const std::exception& e) {
    logLine(std::string("batch could not start: ") + e.what());
  }
  {
    std::lock_guard<std::mutex> lock(state_mutex_);
    batches_skipped_ = engine_->batchesSkipped();
  }
  if (!started) {
    if (on_command) logLine(busy ? "batch: one is still running" : "batch: too few poses yet");
    return;
  }
  if (options_.batch.synchronous) pollBatch(true, true);
}

bool Service::pollBatch(bool wait, bool publish) {
  if (!engine_ || !engine_->batchInFlight()) return false;
  estimate_t seed;
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

void Service::applyReseed(const estimate_t& seed, bool from_journal, refine::BatchRun* run) {
  if (!from_journal && journal_) {
    // Journaled before it is applied: a restart applies the same values at the same point.
    estimate_t record = seed;
    record.utime = nowMicros();
    record.update = updates_;
    try {
      const auto bytes = encodeMessage(record);
      journal_->append(kReseedChannel, record.utime, bytes.data(), static_cast<int>(bytes.size()));
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
    ++reseeds_;
    if (from_journal) ++journal_reseeds_;
    F_ = r.F_rebuilt;
  }
  if (run) {
    run->reseeded = r.applied;
    run->reseed_rejected = !r.applied;
    run->reseed_s = r.stats.time_s;
    run->F_before_reseed = r.F_before;
    run->F_after_reseed = r.F_rebuilt;
    run->reseed_update = updates_;
  }
}

void Service::refine(bool from_journal) {
  if (!engine_) return;
  if (!from_journal) {
    try {
      writeMark(journal_mark_t::REFINE, 0);
    } catch (const std::exception& e) {
      // Unjournaled, a refinement would make the journal's estimate differ from ours.
      logLine(std::string("refinement skipped: the journal cannot take its mark (") + e.what() +
              ")");
      return;
    }
  }
  const auto t0 = std::chrono::steady_clock::now();
  const double before = engine_->objective();
  try {
    engine_->refine();
  } catch (const std::exception& e) {
    logLine(std::string("refinement failed: ") + e.what());
  }
  const double after = engine_->objective();
  std::lock_guard<std::mutex> lock(state_mutex_);
  ++refinements_;
  refine_F_before_ = before;
  refine_F_after_ = after;
  refine_time_s_ = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
  F_ = after;
}

void Service::handleCommand(const command_t& c) {
  switch (c.command) {
    case command_t::REFINE:
      refine(false);
      publishEstimate(true);
      publishStatus();
      break;
    case command_t::PUBLISH_FULL:
      publishEstimate(true);
      break;
    case command_t::SNAPSHOT:
      writeSnapshot(c);
      break;
    case command_t::STATUS:
      publishStatus();
      break;
    case command_t::BATCH:
      startBatch(true);
      break;
    case command_t::CLOSURES:
      writeClosures(c);
      break;
    case command_t::COVARIANCE:
      publishCovariance(c);
      break;
    default:
      logLine("unknown command " + std::to_string(c.command));
  }
}

void Service::writeSnapshot(const command_t& c) {
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
    logLine("snapshot: no estimate yet");
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

void Service::writeClosures(const command_t& c) {
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
    logLine("closures: no report without --robust");
    return;
  }
  if (!engine_) {
    logLine("closures: no estimate yet");
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

void Service::publishCovariance(const command_t& c) {
  covariance_t m;
  m.request = c.utime;
  m.num_ids = 0;
  m.dim = 0;
  {
    std::lock_guard<std::mutex> lock(state_mutex_);
    m.update = updates_;
  }
  try {
    m.ids = covarianceIds(c.path);  // throws on anything but one or two ids
    m.num_ids = static_cast<std::int32_t>(m.ids.size());
    if (!engine_) throw std::runtime_error("no estimate yet");
    const Eigen::MatrixXd sigma = engine_->covariance(m.ids);
    m.dim = static_cast<std::int32_t>(sigma.rows());
    m.matrix.assign(m.dim, std::vector<double>(m.dim));
    for (int r = 0; r < m.dim; ++r)
      for (int k = 0; k < m.dim; ++k) m.matrix[r][k] = sigma(r, k);
  } catch (const std::exception& e) {  // bad ids, an unknown id, a pose not updated yet
    m.dim = 0;
    m.matrix.clear();
    m.error = e.what();
    logLimited("covariance refused", "covariance refused: " + m.error);
  }
  m.utime = nowMicros();
  const auto bytes = encodeMessage(m);
  std::lock_guard<std::mutex> lock(publish_mutex_);
  publish_->publish(channels_.covariance, bytes.data(), static_cast<unsigned>(bytes.size()));
}

void Service::publishEstimate(bool full) {
  if (!engine_) return;
  // What was published while the link was down is lost: the first estimate after it is full.
  if (publish_->takeRecovered()) full = true;
  estimate_t m = engine_->estimate(full);
  m.utime = nowMicros();
  {
    std::lock_guard<std::mutex> lock(state_mutex_);
    m.last_sender = last_sender_;
    m.last_seq = last_seq_;
    m.update = updates_;
    if (full) F_ = m.F;
  }
  const auto bytes = encodeMessage(m);
  std::lock_guard<std::mutex> lock(publish_mutex_);
  publish_->publish(channels_.estimate, bytes.data(), static_cast<unsigned>(bytes.size()));
}

status_t Service::status() const {
  status_t s;
  s.utime = nowMicros();
  {
    std::lock_guard<std::mutex> lock(intake_mutex_);
    const IntakeCounts& c = intake_.counts();
    s.received = c.received;
    s.accepted = c.accepted;
    s.rejected = c.rejected;
    s.duplicates = c.duplicates;
    s.gaps = c.gaps;
    for (const auto& [reason, count] : c.rejected_by_reason) {
      s.reason.push_back(reason);
      s.reason_count.push_back(count);
    }
    const IntakeCounts& p = intake_.priorCounts();
    s.priors_received = p.received;
    s.priors_accepted = p.accepted;
    s.priors_rejected = p.rejected;
    s.priors_duplicates = p.duplicates;
    s.priors_gaps = p.gaps;
    for (const auto& [reason, count] : p.rejected_by_reason) {
      s.reason.push_back("prior " + reason);
      s.reason_count.push_back(count);
    }
    const IntakeCounts& c2 = intake_.commandCounts();
    s.commands_received = c2.received;
    s.commands_accepted = c2.accepted;
    s.commands_rejected = c2.rejected;
    s.commands_duplicates = c2.duplicates;
    for (const auto& [reason, count] : c2.rejected_by_reason) {
      s.reason.push_back("command " + reason);
      s.reason_count.push_back(count);
    }
    s.control_refused = 0;
    for (const auto& [reason, count] : control_refused_) {
      s.reason.push_back("control " + reason);
      s.reason_count.push_back(count);
      s.control_refused += count;
    }
    s.journal_refused = journal_refused_;
    const auto by = [](const IntakeCounts& k, const char* reason) {
      const auto it = k.rejected_by_reason.find(reason);
      return it == k.rejected_by_reason.end() ? std::int64_t{0} : it->second;
    };
    s.refused_senders = by(c, "sender limit") + by(p, "sender limit") + by(c2, "sender limit");
    s.refused_oversize = by(c, "oversize") + by(p, "oversize") + by(c2, "oversize");
    if (const auto it = control_refused_.find("oversize"); it != control_refused_.end()) {
      s.refused_oversize += it->second;
    }
    s.senders = static_cast<int32_t>(intake_.senders(EdgeIntake::Kind::kEdge));
  }
  {
    const LinkCounts r = receive_->counts(), p = publish_->counts();
    s.receive_link_up = receive_->up();
    s.publish_link_up = publish_->up();
    s.link_outages = static_cast<int32_t>(r.outages + p.outages);
    s.publish_failures = p.failed_publishes;
  }
  if (journal_) s.journal_bytes = journal_->bytes();
  std::lock_guard<std::mutex> lock(state_mutex_);
  s.applied = applied_;
  s.rejected += smoother_rejected_;
  if (smoother_rejected_ > 0) {
    s.reason.push_back("smoother");
    s.reason_count.push_back(smoother_rejected_);
  }
  s.priors_applied = priors_applied_;
  s.priors_rejected += smoother_priors_rejected_;
  if (smoother_priors_rejected_ > 0) {
    s.reason.push_back("prior smoother");
    s.reason_count.push_back(smoother_priors_rejected_);
  }
  s.components = components_;
  s.commands_applied = commands_applied_;
  s.commands_refused = commands_refused_;
  for (const auto& [reason, count] : command_refusals_) {
    s.reason.push_back("command refused " + reason);
    s.reason_count.push_back(count);
  }
  s.edges_disabled = edges_disabled_;
  s.pairs_disabled = pairs_disabled_;
  s.last_command_sender = last_command_sender_;
  s.last_command_seq = last_command_seq_;
  s.last_command_result = last_command_result_;
  s.duplicates += smoother_duplicates_;
  s.pending = pending_;
  s.updates = updates_;
  s.queue_depth = static_cast<int32_t>(s.accepted + s.priors_accepted + s.commands_accepted -
                                       applied_ - priors_applied_ - commands_applied_);
  s.held = held_;
  s.poses = static_cast<int32_t>(poses_);
  s.F = F_;
  s.num_reasons = static_cast<int32_t>(s.reason.size());
  const size_t n = latencies_ms_.size();
  const size_t window = std::min(n, static_cast<size_t>(std::max(1, options_.latency_window)));
  const cli::LatencySummary lat = cli::summarizeLatency(std::vector<double>(
      latencies_ms_.end() - static_cast<std::ptrdiff_t>(window), latencies_ms_.end()));
  s.latency_window = static_cast<int32_t>(window);
  s.latency_p50_ms = lat.p50;
  s.latency_p99_ms = lat.p99;
  s.latency_max_ms = lat.max;
  s.refinements = refinements_;
  s.refine_F_before = refine_F_before_;
  s.refine_F_after = refine_F_after_;
  s.refine_time_s = refine_time_s_;
  const refine::BatchRun last = batch_runs_.empty() ? refine::BatchRun() : batch_runs_.back();
  s.batches = static_cast<int32_t>(batch_runs_.size());
  s.batches_skipped = batches_skipped_;
  s.reseeds = reseeds_;
  s.batch_update = last.update;
  s.batch_poses = last.poses;
  s.batch_F_incremental = last.F_incremental;
  s.batch_F = last.F_batch;
  s.batch_F_lm = last.F_lm;
  s.batch_relative_gap = last.relative_gap;
  s.batch_max_translation_diff = last.max_translation_diff;
  s.batch_max_rotation_diff = last.max_rotation_diff;
  s.batch_winner = last.winner;
  s.batch_margin = last.margin;
  s.batch_certified = last.certified;
  s.batch_rank = last.rank;
  s.batch_lambda_min = last.lambda_min;
  s.batch_time_s = last.time_s;
  s.batch_reseeded = last.reseeded;
  s.robust = options_.robust.has_value();
  const OnlineStats& r = robust_stats_;
  s.closures_inlier = r.closures_inlier;
  s.closures_outlier = r.closures_outlier;
  s.closures_trusted = r.closures_trusted;
  s.closures_excluded = r.closures_excluded;
  s.closures_graduating = r.closures_graduating;
  s.closures_total =
      r.closures_inlier + r.closures_outlier + r.closures_trusted + r.closures_excluded;
  s.inlier_threshold = inlier_threshold_;
  s.batch_cancelled = last.cancelled;
  // Read live: the link may have re-created the socket since start() (0 while it is down).
  s.recv_buf_bytes = options_.udpm_port > 0 ? udpReceiveBufferBytes(options_.udpm_port) : 0;
  return s;
}

void Service::publishStatus() {
  if (engine_) {
    const double F = engine_->objective();
    std::lock_guard<std::mutex> lock(state_mutex_);
    F_ = F;
  }
  const auto bytes = encodeMessage(status());
  last_status_ = std::chrono::steady_clock::now();
  std::lock_guard<std::mutex> lock(publish_mutex_);
  publish_->publish(channels_.status, bytes.data(), static_cast<unsigned>(bytes.size()));
}

void Service::replayJournal() {
  const EventLogContents log = readEventLog(options_.journal_path);
  for (const auto& [first, end] : log.damaged) {
    logLine("journal " + options_.journal_path + ": bytes " + std::to_string(first) + " to " +
            std::to_string(end) +
            " are not events (damaged); skipped, the events after them are replayed and the "
            "bytes stay in the file");
  }
  if (log.valid_bytes < log.file_bytes) {
    logLine("journal " + options_.journal_path + ": dropping " +
            std::to_string(log.file_bytes - log.valid_bytes) +
            " bytes of an incomplete event at the end");
  }
  std::deque<Queued> unmarked;
  const std::int64_t prior_hash = prior_t::getHash();
  const std::int64_t command_hash = edge_command_t::getHash();
  const std::int64_t mark_hash = journal_mark_t::getHash();
  const std::int64_t reseed_hash = estimate_t::getHash();
  const auto now = std::chrono::steady_clock::now();
  // In file order: edges and priors re-enter the intake and the queue in the order they were
  // received, and each mark takes the next N of them, whichever kind.
  for (const LogEvent& event : log.events) {
    const std::int64_t hash = leadingHash(event.data);
    const int size = static_cast<int>(event.data.size());
    if (isEdgeMessage(event.data.data(), size) || hash == prior_hash || hash == command_hash) {
      const bool prior = hash == prior_hash, command = hash == command_hash;
      IntakeResult r = command ? intake_.admitCommand(event.data.data(), size)
                       : prior ? intake_.admitPrior(event.data.data(), size)
                               : intake_.admit(event.data.data(), size);
      if (r.verdict != Intake::kAccepted) {
        logLine(std::string("journal: ") +
                (command ? "edge command"
                 : prior ? "prior"
                         : "edge") +
                " (sender " + std::to_string(r.sender) + " seq " + std::to_string(r.seq) +
                ") skipped on replay: " + r.reason);
        continue;
      }
      unmarked.push_back(queued(std::move(r), now));
    } else if (hash == mark_hash) {
      journal_mark_t m;
      if (decodeMessage(event.data.data(), size, &m) != MessageProblem::kNone) continue;
      if (m.kind == journal_mark_t::UPDATE) {
        const size_t n = std::min(unmarked.size(), static_cast<size_t>(std::max(0, m.edges)));
        if (n == 0) continue;
        std::vector<Queued> batch(std::make_move_iterator(unmarked.begin()),
                                  std::make_move_iterator(unmarked.begin() + n));
        unmarked.erase(unmarked.begin(), unmarked.begin() + n);
        applyBatch(batch, true);
      } else if (m.kind == journal_mark_t::REFINE) {
        refine(true);
      }
    } else if (hash == reseed_hash && event.channel == kReseedChannel) {
      estimate_t seed;
      if (decodeMessage(event.data.data(), size, &seed) != MessageProblem::kNone || !engine_) {
        logLine("journal: a reseed record could not be used; skipped");
        continue;
      }
      applyReseed(seed, true, nullptr);
    }
  }
  journal_ = std::make_unique<EventLogWriter>(
      options_.journal_path, log.valid_bytes,
      EventLogWriterOptions{options_.fsync_interval_ms, options_.journal_max_bytes,
                            options_.journal_reserve_bytes});
  // Accepted but not yet applied when the journal ended: the first update takes them.
  queue_.assign(std::make_move_iterator(unmarked.begin()), std::make_move_iterator(unmarked.end()));
  if (!log.events.empty()) {
    logLine("journal " + options_.journal_path + ": replayed " + std::to_string(journal_edges_) +
            " edges, " + std::to_string(journal_priors_) + " priors and " +
            std::to_string(journal_commands_) + " edge commands in " +
            std::to_string(journal_updates_) + " updates; " + std::to_string(queue_.size()) +
            " to apply");
  }
}

}  // namespace arbor::serve
