// arbor serve: ingest edges, priors and edge commands published over LCM into the incremental
// smoother and publish the estimate (tools/serve/serve_service.h). SIGINT/SIGTERM end it cleanly.
#include "arbor_slam/tools/cli/serve_command.h"

#include <algorithm>
#include <atomic>
#include <cmath>
#include <csignal>
#include <iostream>
#include <limits>
#include <memory>
#include <set>
#include <sstream>
#include <thread>

#include <pthread.h>
#include <sys/stat.h>

#include <lcm/lcm-cpp.hpp>
#include <nlohmann/json.hpp>

#include "arbor_slam/core/heap_policy.h"
#include "arbor_slam/tools/cli/batch_refinement.h"
#include "arbor_slam/tools/cli/bus_key_flag.h"
#include "arbor_slam/tools/cli/cli_common.h"
#include "arbor_slam/tools/cli/commands.h"
#include "arbor_slam/tools/cli/flag_set.h"
#include "arbor_slam/tools/cli/output_files.h"
#include "arbor_slam/tools/cli/robust_flags.h"
#include "arbor_slam/tools/cli/smoother_flags.h"
#include "arbor_slam/tools/serve/closure_report.h"
#include "arbor_slam/tools/serve/lcm_tuning.h"
#include "arbor_slam/tools/serve/serve_service.h"

namespace arbor::cli {
namespace {

namespace po = boost::program_options;

// A directory of --journal DIR or --snapshot-dir DIR, created if missing.
void makeDirectory(const std::string& dir, const std::string& what) {
  if (::mkdir(dir.c_str(), 0755) != 0 && errno != EEXIST) {
    throw std::runtime_error("cannot create " + what + " directory " + dir);
  }
  struct stat st;
  if (::stat(dir.c_str(), &st) != 0 || !S_ISDIR(st.st_mode)) {
    throw std::runtime_error(what + " " + dir + " is not a directory");
  }
}

// --fsync: update (once before each update), edge, N ms, never.
void parseFsync(const std::string& text, serve::ServeOptions* options) {
  options->fsync_before_update = text == "update";
  options->fsync_interval_ms = -1;
  if (text == "update" || text == "never") return;
  if (text == "edge") {
    options->fsync_interval_ms = 0;
    return;
  }
  try {
    size_t used = 0;
    const int ms = std::stoi(text, &used);
    if (used == text.size() && ms > 0) {
      options->fsync_interval_ms = ms;
      return;
    }
  } catch (const std::exception&) {
  }
  throw UsageError("--fsync must be update, edge, never or a number of ms > 0, not '" + text + "'");
}

int parsePublishMode(const std::string& text) {
  if (text == "changed") return 0;
  if (text == "full") return 1;
  try {
    size_t used = 0;
    const int n = std::stoi(text, &used);
    if (used == text.size() && n > 0) return n;
  } catch (const std::exception&) {
  }
  throw UsageError("--publish must be changed, full or N > 0, not '" + text + "'");
}

// --exit-refine-budget: seconds ≥ 0, or none (to convergence).
double parseExitBudget(const std::string& text) {
  if (text == "none") return std::numeric_limits<double>::infinity();
  try {
    size_t used = 0;
    const double s = std::stod(text, &used);
    if (used == text.size() && std::isfinite(s) && s >= 0) return s;
  } catch (const std::exception&) {
  }
  throw UsageError("--exit-refine-budget must be seconds >= 0 or none, not '" + text + "'");
}

}  // namespace

namespace {

// What the flags are read into before the checks turn them into a ServeCommandLine.
struct ServeFlagValues {
  ServeCommandLine line;
  std::string fsync = "update", publish = "changed", batch, format;
  bool no_refine = false;
  std::string exit_budget = "1";
  long long max_senders = static_cast<long long>(line.options.max_senders);
  double gap_hold_s = 2;  // --gap-hold (the library's default is off)
  long long reorder_limit = static_cast<long long>(line.options.reorder_limit);
  long long max_backlog = static_cast<long long>(line.options.max_backlog);
};

const char* const kService = "Service";
const char* const kOutput = "Output";
const char* const kBatch = "Batch refinement";

// Every flag of `arbor serve`, bound to `v`; each is declared here or in its table only.
FlagSet serveFlagSet(ServeFlagValues& v) {
  ServeCommandLine& line = v.line;
  serve::ServeOptions& options = line.options;
  FlagSet flags("arbor serve [options]",
                {"arbor serve --journal /var/lib/arbor --robust -o map.g2o",
                 "arbor serve --config serve.toml   (write one: arbor serve ... --print-config)"});
  flags.add(Tier::kCommon, kService)("lcm-url", po::value(&line.url)->value_name("URL"),
                                     "LCM provider URL (default: LCM_DEFAULT_URL / LCM's default)")(
      "journal", po::value(&line.journal_dir)->value_name("DIR"),
      "directory of the journal (journal.lcmlog); replayed on start")(
      "publish", po::value(&v.publish)->default_value("changed")->value_name("changed|full|N"),
      "estimates: changed (poses that changed), full, or N (full every N updates)");
  addBusKeyFlag(flags.add(Tier::kCommon, kService), &line.key_file);
  flags.add(Tier::kAdvanced, kService)(
      "channel-prefix", po::value(&options.channel_prefix),
      "prefix of ARBOR_EDGES, ARBOR_PRIORS, ARBOR_ESTIMATE, ARBOR_STATUS, ARBOR_COMMAND")(
      "fsync", po::value(&v.fsync)->default_value("update"),
      "journal fsync: update (before each update), edge, N (at most every N ms) or never")(
      "dim", po::value(&options.dim)->default_value(0),
      "2 or 3; an edge or prior of the other dimension is refused ('dim'). 0: the first edge's "
      "(the journal's first on a restart); set it where others share the bus")(
      "intake-window", po::value(&options.intake_window)->default_value(options.intake_window),
      "seqs remembered per sender for duplicate detection (older ones are refused as stale); a "
      "seq W or more above its sender's highest is held until 3 consecutive seqs confirm it")(
      "max-senders", po::value(&v.max_senders)->default_value(v.max_senders),
      "sender tables per stream (edges, priors, edge commands); a new sender takes the place of "
      "the least recently heard one (counted as senders_evicted)")(
      "gap-hold", po::value(&v.gap_hold_s)->default_value(v.gap_hold_s)->value_name("S"),
      "loss recovery: an edge or prior after a gap in its sender's seqs waits up to S seconds "
      "for the gap to be resent (serve asks on ARBOR_RESEND), so the stream is applied in seq "
      "order; then the gap is given up (0: off, applied as received; docs/lcm.md)")(
      "reorder-limit", po::value(&v.reorder_limit)->default_value(v.reorder_limit)->value_name("N"),
      "loss recovery: messages held per sender and stream while a gap waits; beyond, the oldest "
      "gap is given up")(
      "max-backlog", po::value(&v.max_backlog)->default_value(v.max_backlog)->value_name("N"),
      "messages waiting for the smoother at most; past it a message is dropped unread, counted "
      "(backlog_dropped) and left to loss recovery, never one already journaled")(
      "snapshot-dir", po::value(&options.snapshot_dir),
      "directory command SNAPSHOT writes into (a plain file name from the message; never over a "
      "file this service did not create); unset: SNAPSHOT refused")(
      "journal-max-bytes", po::value(&options.journal_max_bytes)->default_value(0),
      "the journal is full at this size: further edges are refused, as on a full disk (0: no "
      "limit)")(
      "recv-buf", po::value(&line.recv_buf_bytes),
      "udpm: the receive buffer in bytes (LCM's recv_buf_size; capped by net.core.rmem_max; "
      "default 4194304 unless the URL names recv_buf_size, which this flag replaces; docs/lcm.md)")(
      "status-period", po::value(&options.status_period_s)->default_value(1.0),
      "seconds between status messages")(
      "bounded-heap", po::bool_switch(&line.bounded_heap),
      "return freed clique storage to the system: glibc's mmap threshold fixed at 1 MiB "
      "(core/heap_policy.h). Lowers the peak of very large graphs; costs page faults where "
      "large tops are re-eliminated every update (docs/design.md, \"Memory\")");
  flags.add(Tier::kCommon, kOutput)("output,o", po::value(&line.output)->value_name("OUT"),
                                    "on exit, write the estimate (as --format)")(
      "json", po::bool_switch(&line.json), "on exit, print one JSON object");
  flags.add(Tier::kAdvanced, kOutput)(
      "format", po::value(&v.format)->value_name("g2o|tum|kitti"),
      "of -o: g2o (the graph with the edges applied) | tum (`time tx ty tz qx qy qz qw` a line, "
      "the time the utime in seconds of the edge that created the pose) | kitti (3x4 [R t] "
      "row-major a line), by ascending id; default: -o's extension (.g2o, .tum, .kitti; .txt "
      "needs --format), else g2o; docs/files.md")(
      "no-refine", po::bool_switch(&v.no_refine),
      "on exit, skip the relinearise-all pass (the raw incremental estimate)")(
      "exit-refine-budget", po::value(&v.exit_budget)->default_value(v.exit_budget),
      "seconds the exit refinement may take: it stops at the first iteration boundary after "
      "them (none: to convergence, however long; a second SIGINT/SIGTERM cuts it at once)");
  flags.add(smootherOptionTable());
  flags.add(Tier::kCommon, kBatch)(
      "batch", po::value(&v.batch)->value_name("SOLVER"),
      (refine::batchSolverNames(true) +
       ": batch refinement in the background (every --batch-every updates and on command BATCH; "
       "lm when absent)")
          .c_str())("batch-every",
                    po::value(&options.batch.every)->default_value(0)->value_name("N"),
                    "a background batch every N updates (needs --batch; 0: only on command BATCH)");
  flags.add(Tier::kAdvanced, kBatch)(
      "reseed", po::bool_switch(&options.batch.reseed),
      "a batch estimate with lower F becomes the linearisation point (journaled)");
  addRobustFlags(flags,
                 "robust to false loop closures: graduated non-convexity per loop closure in the "
                 "Bayes tree (riSAM-style), odometry (|i-j| = 1) trusted; edge_t's trust and "
                 "kernel choose per edge");
  flags.add(onlineRobustOptionTable());
  flags.allowConfig();
  return flags;
}

}  // namespace

std::vector<FlagInfo> serveFlags() {
  ServeFlagValues v;
  return serveFlagSet(v).flags();
}

std::optional<ServeCommandLine> parseServeCommandLine(const std::vector<std::string>& args,
                                                      std::ostream& out) {
  ServeFlagValues v;
  const FlagSet flags = serveFlagSet(v);
  const std::optional<po::variables_map> parsed = flags.parse(args);
  if (!parsed) return std::nullopt;
  const po::variables_map& vm = *parsed;
  ServeCommandLine& line = v.line;
  serve::ServeOptions& options = line.options;
  const std::string &fsync = v.fsync, &publish = v.publish, &batch = v.batch, &format = v.format,
                    &exit_budget = v.exit_budget;
  const bool no_refine = v.no_refine;
  const long long max_senders = v.max_senders;
  options.smoother = readSmootherFlags(vm);
  options.bus_keys = readBusKeyFlag(line.key_file);
  if (options.dim != 0 && options.dim != 2 && options.dim != 3) {
    throw UsageError("--dim must be 0, 2 or 3, not '" + std::to_string(options.dim) + "'");
  }
  if (!(options.status_period_s > 0)) {
    std::ostringstream value;
    value << options.status_period_s;
    throw UsageError("--status-period must be > 0, not '" + value.str() + "'");
  }
  if (options.intake_window < 1) {
    throw UsageError("--intake-window must be >= 1, not '" + std::to_string(options.intake_window) +
                     "'");
  }
  if (max_senders < 1) {
    throw UsageError("--max-senders must be >= 1, not '" + std::to_string(max_senders) + "'");
  }
  options.max_senders = static_cast<std::size_t>(max_senders);
  if (!(v.gap_hold_s >= 0 && v.gap_hold_s <= 3600)) {
    std::ostringstream value;
    value << v.gap_hold_s;
    throw UsageError("--gap-hold must be seconds in 0..3600, not '" + value.str() + "'");
  }
  options.gap_hold = std::chrono::milliseconds(std::llround(v.gap_hold_s * 1e3));
  if (v.reorder_limit < 1 || v.reorder_limit > (1LL << 24)) {
    throw UsageError("--reorder-limit must be in 1..16777216, not '" +
                     std::to_string(v.reorder_limit) + "'");
  }
  options.reorder_limit = static_cast<std::size_t>(v.reorder_limit);
  if (v.max_backlog < 1 || v.max_backlog > (1LL << 30)) {
    throw UsageError("--max-backlog must be in 1..1073741824, not '" +
                     std::to_string(v.max_backlog) + "'");
  }
  options.max_backlog = static_cast<std::size_t>(v.max_backlog);
  if (options.journal_max_bytes < 0 ||
      (options.journal_max_bytes > 0 &&
       options.journal_max_bytes <= 2 * options.journal_reserve_bytes)) {
    throw UsageError("--journal-max-bytes must be 0 or more than " +
                     std::to_string(2 * options.journal_reserve_bytes) +
                     " (twice the room kept for update marks), not '" +
                     std::to_string(options.journal_max_bytes) + "'");
  }
  if (!batch.empty()) {
    try {
      options.batch.solver = refine::parseBatchSolver(batch, "--batch", /*refinement_only=*/true);
    } catch (const std::invalid_argument& e) {
      throw UsageError(e.what());
    }
  }
  if (options.batch.every < 0) {
    throw UsageError("--batch-every must be >= 0, not '" + std::to_string(options.batch.every) +
                     "'");
  }
  if (batch.empty() && options.batch.every > 0)
    throw UsageError("--batch-every needs --batch " + refine::batchSolverNames(true, "|"));
  line.robust = readRobustFlags(vm, /*allow_auto=*/false);
  RobustOptions robust;
  readOnlineRobustFlags(vm, line.robust.robust, &robust);
  requireInlineWithRobust(line.robust.robust, options.smoother);
  if (line.robust.robust) {
    robust.kernel = line.robust.kernel;
    robust.threshold = line.robust.threshold;
    options.robust = robust;
  }
  if (!format.empty() && line.output.empty()) throw UsageError("--format needs --output");
  line.format = outputFormat(line.output, format);
  parseFsync(fsync, &options);
  options.full_every = parsePublishMode(publish);
  options.refine_on_exit = !no_refine;
  options.exit_refine_budget_s = parseExitBudget(exit_budget);
  if (!line.journal_dir.empty()) options.journal_path = line.journal_dir + "/journal.lcmlog";
  if (vm.count("recv-buf") && line.recv_buf_bytes <= 0) {
    throw UsageError("--recv-buf must be > 0 bytes, not '" + std::to_string(line.recv_buf_bytes) +
                     "'");
  }
  if (serve::isUdpmUrl(line.url)) {
    line.url =
        line.recv_buf_bytes > 0
            ? serve::withReceiveBuffer(line.url, line.recv_buf_bytes, serve::UrlOption::kReplace)
            : serve::withReceiveBuffer(line.url, ServeCommandLine::kDefaultRecvBufBytes);
    options.udpm_port = serve::udpmPort(line.url);
  } else if (vm.count("recv-buf")) {
    throw UsageError("--recv-buf applies to udpm:// only, not '" + line.url + "'");
  }
  if (flags.printConfig(vm, out)) return std::nullopt;
  return std::move(line);
}

int serveCommand(const std::vector<std::string>& args) {
  std::optional<ServeCommandLine> line = parseServeCommandLine(args);
  if (!line) return 0;
  requireWritable("--output", line->output);
  requireWritable("--rejected-out", line->robust.rejected_out);
  if (line->bounded_heap) useBoundedHeap();
  serve::ServeOptions& options = line->options;
  const std::string& url = line->url;
  const std::string& output = line->output;
  options.log = &std::cerr;
  if (!line->journal_dir.empty()) makeDirectory(line->journal_dir, "journal");
  if (!options.snapshot_dir.empty()) makeDirectory(options.snapshot_dir, "snapshot");

  // Every thread (LCM's and ours) inherits this mask; only sigwait below sees the signals.
  sigset_t signals;
  sigemptyset(&signals);
  sigaddset(&signals, SIGINT);
  sigaddset(&signals, SIGTERM);
  // With --key, SIGHUP reads the key file again (rotation without a restart).
  sigset_t waited = signals;
  if (!line->key_file.empty()) sigaddset(&waited, SIGHUP);
  pthread_sigmask(SIG_BLOCK, &waited, nullptr);

  // Two links, one to receive and one to publish (see serve::Service), each re-created after a
  // transport fault (serve::LinkWatch); memq:// is private to an instance, so there one serves
  // both and is never re-created. udpm://: serve reads the datagrams itself (serve::UdpmReceiver:
  // checked, reassembled in bounded memory) and hands complete messages to its subscriptions
  // through a memq:// inbox; the publishing instance is never asked to receive, so liblcm's
  // udpm receive thread never starts in this process.
  const auto log = [](const std::string& text) {
    std::cerr << "arbor serve: " << text << std::endl;
  };
  serve::LinkWatchOptions receive_options;
  receive_options.url = url;
  receive_options.name = "receive link";
  receive_options.probe_channel = serve::Channels::withPrefix(options.channel_prefix).link_probe;
  receive_options.log = log;
  serve::LinkWatchOptions publish_options = receive_options;
  publish_options.name = "publish link";
  publish_options.probe_channel.clear();
  std::unique_ptr<lcm::LCM> memq;
  std::unique_ptr<serve::LinkWatch> receive, publisher;
  std::unique_ptr<serve::UdpmReceiver> datagrams;
  if (url.rfind("memq://", 0) == 0) {
    memq = std::make_unique<lcm::LCM>(url);
    if (!memq->good()) throw std::runtime_error("cannot open LCM at '" + url + "'");
    receive = std::make_unique<serve::LinkWatch>(*memq, receive_options);
    publisher = std::make_unique<serve::LinkWatch>(*memq, publish_options);
  } else if (serve::isUdpmUrl(url)) {
    const serve::Channels channels = serve::Channels::withPrefix(options.channel_prefix);
    // Nothing larger than the largest message a channel accepts is reassembled.
    const serve::MessageLimits& m = options.message_limits;
    serve::DatagramLimits limits;
    limits.max_message_bytes = static_cast<std::uint32_t>(
        std::max({m.edge, m.prior, m.edge_command, m.command, m.resend_window}));
    if (!options.bus_keys.empty()) limits.max_message_bytes += serve::kEnvelopeOverhead;
    datagrams = std::make_unique<serve::UdpmReceiver>(url, channels.received(), log, limits);
    memq = std::make_unique<lcm::LCM>("memq://");
    if (!memq->good()) throw std::runtime_error("cannot open LCM at 'memq://'");
    receive = std::make_unique<serve::LinkWatch>(*memq, receive_options);
    publish_options.publish_only = true;
    publisher = std::make_unique<serve::LinkWatch>(publish_options);
  } else {
    receive = std::make_unique<serve::LinkWatch>(receive_options);
    publisher = std::make_unique<serve::LinkWatch>(publish_options);
  }
  serve::Service service(*receive, *publisher, options, datagrams.get());
  service.start();
  std::cerr << "arbor serve: listening on " << service.channels().edges << std::endl;
  int signal = 0;
  while (sigwait(&waited, &signal) == 0 && signal == SIGHUP) {
    try {
      service.setBusKeys(serve::readBusKeyFile(line->key_file));
    } catch (const std::exception& e) {
      std::cerr << "arbor serve: SIGHUP: " << e.what() << "; keeping the keys in use" << std::endl;
    }
  }
  std::cerr << "arbor serve: " << (signal == SIGINT ? "SIGINT" : "SIGTERM") << ", stopping"
            << std::endl;
  // A second signal while stopping cuts the exit refinement (and a batch) at its next check.
  std::atomic<bool> stopped{false};
  std::thread second_signal([&] {
    const timespec tick{0, 50 * 1000 * 1000};
    while (!stopped) {
      if (sigtimedwait(&signals, nullptr, &tick) < 0) continue;
      std::cerr << "arbor serve: a second signal, cutting the exit refinement" << std::endl;
      service.cancelExit();
    }
  });
  service.stop();
  stopped = true;
  second_signal.join();
  const serve::ServeSummary& s = service.summary();
  if (!output.empty() && !service.writeEstimate(output, line->format)) {
    std::cerr << "arbor serve: no edge was applied; " << output << " not written\n";
  }
  if (!line->robust.rejected_out.empty())
    serve::writeRejectedEdges(line->robust.rejected_out, s.closures);
  if (line->json) {
    nlohmann::json reasons = nlohmann::json::object();
    for (const auto& [reason, count] : s.intake.rejected_by_reason) reasons[reason] = count;
    if (s.smoother_rejected) reasons["smoother"] = s.smoother_rejected;
    nlohmann::json j = {
        {"received", s.intake.received},
        {"accepted", s.intake.accepted},
        {"applied", s.applied},
        {"rejected", s.intake.rejected + s.smoother_rejected},
        {"rejected_by_reason", reasons},
        {"duplicates", s.intake.duplicates + s.smoother_duplicates},
        {"gaps", s.intake.gaps},
        {"jumps_held", s.intake.held},
        {"jumps_confirmed", s.intake.jumps_confirmed},
        {"senders_evicted", s.intake.senders_evicted},
        {"loss_recovery",
         {{"held", s.loss.held},
          {"reordered", s.loss.reordered},
          {"given_up", s.loss.given_up},
          {"gaps_given_up", s.loss.gaps_given_up},
          {"late", s.loss.late},
          {"requests", s.loss.requests}}},
        {"updates", s.updates},
        {"poses", s.poses},
        {"pending", s.pending},
        {"journal_edges", s.journal_edges},
        {"journal_updates", s.journal_updates},
        {"refinements", s.refinements},
        {"exit_refine",
         {{"iterations", s.exit_refine_iterations},
          {"cut", s.exit_refine_cut},
          {"time_s", s.exit_refine_time_s}}},
        {"batches_skipped", s.batches_skipped},
        {"reseeds", s.reseeds},
        {"journal_reseeds", s.journal_reseeds},
        {"F_final", s.F_final},
        {"recv_buf_bytes", s.recv_buf_bytes},
        {"latency_ms", {{"p50", s.latency.p50}, {"p99", s.latency.p99}, {"max", s.latency.max}}},
        {"transport_ms",
         {{"p50", s.transport.p50}, {"p99", s.transport.p99}, {"max", s.transport.max}}},
    };
    nlohmann::json prior_reasons = nlohmann::json::object();
    for (const auto& [reason, count] : s.prior_intake.rejected_by_reason)
      prior_reasons[reason] = count;
    if (s.smoother_priors_rejected) prior_reasons["smoother"] = s.smoother_priors_rejected;
    j["priors"] = {
        {"received", s.prior_intake.received},
        {"accepted", s.prior_intake.accepted},
        {"applied", s.priors_applied},
        {"rejected", s.prior_intake.rejected + s.smoother_priors_rejected},
        {"rejected_by_reason", prior_reasons},
        {"duplicates", s.prior_intake.duplicates},
        {"gaps", s.prior_intake.gaps},
        {"jumps_held", s.prior_intake.held},
        {"jumps_confirmed", s.prior_intake.jumps_confirmed},
        {"senders_evicted", s.prior_intake.senders_evicted},
        {"journal_priors", s.journal_priors},
    };
    nlohmann::json command_reasons = nlohmann::json::object();
    for (const auto& [reason, count] : s.command_intake.rejected_by_reason)
      command_reasons[reason] = count;
    nlohmann::json refused = nlohmann::json::object();
    for (const auto& [reason, count] : s.commands_refused_by_reason) refused[reason] = count;
    j["commands"] = {
        {"received", s.command_intake.received},
        {"accepted", s.command_intake.accepted},
        {"applied", s.commands_applied},
        {"rejected", s.command_intake.rejected},
        {"rejected_by_reason", command_reasons},
        {"refused", s.commands_refused},
        {"refused_by_reason", refused},
        {"duplicates", s.command_intake.duplicates},
        {"journal_commands", s.journal_commands},
        {"gaps", s.command_intake.gaps},
        {"jumps_held", s.command_intake.held},
        {"jumps_confirmed", s.command_intake.jumps_confirmed},
        {"senders_evicted", s.command_intake.senders_evicted},
    };
    nlohmann::json control = nlohmann::json::object();
    for (const auto& [reason, count] : s.control_refused) control[reason] = count;
    j["faults"] = {
        {"journal_refused", s.journal_refused},
        {"backlog_dropped", s.backlog_dropped},
        {"journal_damaged",
         {{"events", s.journal_damaged.events},
          {"tail_bytes", s.journal_damaged.tail_bytes},
          {"unchecked", s.journal_damaged.unchecked}}},
        {"held_at_stop", s.held_at_stop},
        {"link_outages", s.link_outages},
        {"control_refused", control},
        {"datagrams_refused", s.datagrams_refused},
        {"datagram_partials_dropped", s.datagram_partials_dropped},
        {"auth_refused", s.auth_refused},
    };
    j["edges_disabled"] = s.edges_disabled;
    j["pairs_disabled"] = s.pairs_disabled;
    j["components"] = s.components;
    if (options.robust) {
      int counts[4] = {0, 0, 0, 0};
      int graduating = 0;
      for (const ClosureReport& c : s.closures) {
        ++counts[static_cast<int>(c.status)];
        graduating += c.graduating;
      }
      j["robust"] = {
          {"kernel", toString(options.robust->kernel)},
          {"noise_scale_mode", toString(options.robust->scale)},
          {"rules_off", options.robust->rules_off.toString()},
          {"inlier_threshold", s.inlier_threshold},
          {"closures_inlier", counts[static_cast<int>(ClosureStatus::kInlier)]},
          {"closures_outlier", counts[static_cast<int>(ClosureStatus::kOutlier)]},
          {"closures_trusted", counts[static_cast<int>(ClosureStatus::kTrusted)]},
          {"closures_excluded", counts[static_cast<int>(ClosureStatus::kExcluded)]},
          {"closures_graduating", graduating},
      };
      if (!line->robust.rejected_out.empty()) j["rejected_out"] = line->robust.rejected_out;
    }
    j["batches"] = nlohmann::json::array();
    for (const auto& b : s.batches) j["batches"].push_back(batchRunJson(b));
    std::cout << j.dump() << std::endl;
  }
  return 0;
}

}  // namespace arbor::cli
