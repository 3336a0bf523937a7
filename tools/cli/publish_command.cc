// arbor publish FILE: stream a pose-graph file's edges over LCM as edge_t, in the order `arbor
// replay` feeds them (seq = position in that order, from 1), and its priors as prior_t, each
// right after the edge that introduces its pose (tools/cli/publish_stream.h), at a rate or as a
// burst; optionally wait for the estimate that covers the last edge and report publish →
// estimate latency.
#include <atomic>
#include <chrono>
#include <condition_variable>
#include <iomanip>
#include <iostream>
#include <mutex>
#include <thread>

#include <lcm/lcm-cpp.hpp>
#include <nlohmann/json.hpp>

#include "arbor_slam/core/latency_summary.h"
#include "arbor_slam/io/edge_choice_file.h"
#include "arbor_slam/io/lcm_messages.h"
#include "arbor_slam/io/pose_graph_file.h"
#include "arbor_slam/tools/cli/bus_key_flag.h"
#include "arbor_slam/tools/cli/cli_common.h"
#include "arbor_slam/tools/cli/commands.h"
#include "arbor_slam/tools/cli/publish_command.h"
#include "arbor_slam/tools/cli/publish_stream.h"
#include "arbor_slam/tools/cli/resend_window.h"
#include "arbor_slam/tools/serve/lcm_tuning.h"
#include "arbor_slam/tools/serve/serve_service.h"

namespace arbor::cli {
namespace {

namespace po = boost::program_options;
using Clock = std::chrono::steady_clock;

struct PublishRun : PublishOptions {
  serve::BusKeyring keys;  // of --key (none without it)
};

// Listens on ARBOR_ESTIMATE / ARBOR_STATUS while edges go out: which seq numbers of our sender
// are covered by an estimate, and when.
class Listener {
 public:
  Listener(lcm::LCM& lcm, const serve::Channels& channels, std::int64_t sender, size_t slots,
           std::int64_t first_seq, serve::BusAuth* auth)
      : lcm_(lcm),
        auth_(auth),
        sender_(sender),
        first_seq_(first_seq),
        sent_(slots),
        latency_ms_(slots, -1) {
    subs_.push_back(lcm_.subscribe(channels.estimate, &Listener::onEstimate, this));
    subs_.push_back(lcm_.subscribe(channels.status, &Listener::onStatus, this));
    for (auto* s : subs_) s->setQueueCapacity(0);
    thread_ = std::thread([this] {
      while (!stop_) {
        serve::armQuickAck(lcm_);
        lcm_.handleTimeout(20);
      }
    });
  }
  ~Listener() {
    stop_ = true;
    thread_.join();
    for (auto* s : subs_) lcm_.unsubscribe(s);
  }
  void sent(size_t slot) {
    std::lock_guard<std::mutex> lock(mutex_);
    sent_[slot] = Clock::now();
  }
  bool waitStatus(double timeout_s) {
    std::unique_lock<std::mutex> lock(mutex_);
    return cv_.wait_for(lock, std::chrono::duration<double>(timeout_s),
                        [&] { return status_seen_; });
  }
  bool waitCovered(std::int64_t seq, double timeout_s) {
    std::unique_lock<std::mutex> lock(mutex_);
    return cv_.wait_for(lock, std::chrono::duration<double>(timeout_s),
                        [&] { return covered_ >= seq; });
  }
  std::vector<double> latencies() {
    std::lock_guard<std::mutex> lock(mutex_);
    std::vector<double> out;
    for (double ms : latency_ms_) {
      if (ms >= 0) out.push_back(ms);
    }
    return out;
  }
  estimate_t lastEstimate() {
    std::lock_guard<std::mutex> lock(mutex_);
    return last_;
  }

 private:
  void onEstimate(const lcm::ReceiveBuffer* rbuf, const std::string& channel) {
    const auto now = Clock::now();
    const std::uint8_t* data = nullptr;
    int size = 0;
    if (!openFromBus(auth_, channel, rbuf, &data, &size)) return;
    estimate_t m;
    if (decodeMessage(data, size, &m) != MessageProblem::kNone) return;
    std::lock_guard<std::mutex> lock(mutex_);
    last_ = m;
    if (m.last_sender != sender_ || m.last_seq <= covered_) return;
    for (std::int64_t seq = std::max(covered_ + 1, first_seq_); seq <= m.last_seq; ++seq) {
      const size_t slot = static_cast<size_t>(seq - first_seq_);
      if (slot >= sent_.size()) break;
      latency_ms_[slot] = std::chrono::duration<double, std::milli>(now - sent_[slot]).count();
    }
    covered_ = m.last_seq;
    cv_.notify_all();
  }
  void onStatus(const lcm::ReceiveBuffer* rbuf, const std::string& channel) {
    const std::uint8_t* data = nullptr;
    int size = 0;
    if (!openFromBus(auth_, channel, rbuf, &data, &size)) return;
    std::lock_guard<std::mutex> lock(mutex_);
    status_seen_ = true;
    cv_.notify_all();
  }

  lcm::LCM& lcm_;
  serve::BusAuth* auth_;  // with --key (else null)
  std::int64_t sender_, first_seq_;
  std::mutex mutex_;
  std::condition_variable cv_;
  std::vector<Clock::time_point> sent_;
  std::vector<double> latency_ms_;
  std::int64_t covered_ = 0;
  bool status_seen_ = false;
  estimate_t last_;
  std::vector<lcm::Subscription*> subs_;
  std::atomic<bool> stop_{false};
  std::thread thread_;
};

// Publishes on one instance from two threads (the stream, and the resends), one at a time.
class BusPublisher {
 public:
  BusPublisher(lcm::LCM& lcm, serve::BusAuth* auth) : lcm_(lcm), auth_(auth) {}
  int publish(const std::string& channel, const std::vector<std::uint8_t>& bytes) {
    std::lock_guard<std::mutex> lock(mutex_);
    return publishOnBus(lcm_, auth_, channel, bytes);
  }

 private:
  lcm::LCM& lcm_;
  serve::BusAuth* auth_;
  std::mutex mutex_;
};

// --resend-window: listens on ARBOR_RESEND (an instance of its own) and answers serve's resend
// requests for our sender from the window of what was sent (tools/cli/resend_window.h).
class Resender {
 public:
  Resender(const std::string& url, const serve::Channels& channels, std::int64_t sender,
           std::size_t capacity, serve::BusAuth* auth, BusPublisher& out)
      : lcm_(url), channels_(channels), auth_(auth), out_(out), window_(capacity, sender) {
    if (!lcm_.good()) throw std::runtime_error("cannot open LCM at '" + url + "'");
    serve::tuneLcmTransport(lcm_, url);
    sub_ = lcm_.subscribe(channels.resend, &Resender::onRequest, this);
    sub_->setQueueCapacity(0);
    thread_ = std::thread([this] {
      while (!stop_) {
        serve::armQuickAck(lcm_);
        lcm_.handleTimeout(20);
      }
    });
  }
  ~Resender() {
    stop_ = true;
    thread_.join();
    lcm_.unsubscribe(sub_);
  }
  void sent(bool prior, std::int64_t seq, const std::string& channel,
            const std::vector<std::uint8_t>& bytes) {
    std::lock_guard<std::mutex> lock(mutex_);
    window_.sent(prior, seq, channel, bytes, Clock::now());
  }
  // After the stream: answers requests until serve settled both streams up to their last seq
  // (probing the tail meanwhile), or the timeout.
  bool waitAcknowledged(std::int64_t last_edge, std::int64_t last_prior, double timeout_s) {
    const auto end = Clock::now() + std::chrono::duration<double>(timeout_s);
    {
      std::lock_guard<std::mutex> lock(mutex_);
      window_.finished();
    }
    for (;;) {
      {
        std::lock_guard<std::mutex> lock(mutex_);
        if (window_.acknowledged(false, last_edge) && window_.acknowledged(true, last_prior))
          return true;
        for (const ResendWindow::Entry* e : window_.tailProbes(Clock::now()))
          out_.publish(e->channel, e->bytes);
      }
      if (Clock::now() > end) return false;
      std::this_thread::sleep_for(std::chrono::milliseconds(50));
    }
  }
  ResendWindow::Counts counts() {
    std::lock_guard<std::mutex> lock(mutex_);
    return window_.counts();
  }

 private:
  void onRequest(const lcm::ReceiveBuffer* rbuf, const std::string& channel) {
    const std::uint8_t* data = nullptr;
    int size = 0;
    if (!openFromBus(auth_, channel, rbuf, &data, &size)) return;
    const ResendDecoding d = decodeResend(data, size);
    if (!d.ok()) {
      if (bad_++ == 0)
        std::cerr << "arbor publish: refused a resend_t on " << channel << ": "
                  << toString(d.problem) << ": " << d.detail << "\n";
      return;
    }
    std::lock_guard<std::mutex> lock(mutex_);
    const ResendWindow::Answer a = window_.request(d.message, Clock::now());
    for (const ResendWindow::Entry* e : a.resend) out_.publish(e->channel, e->bytes);
    if (a.window) {
      ResendMessage w = *a.window;
      w.utime = serve::nowMicros();
      out_.publish(channels_.resend_window, encodeMessage(makeResendMessage(w)));
    }
  }

  lcm::LCM lcm_;
  serve::Channels channels_;
  serve::BusAuth* auth_;
  BusPublisher& out_;
  std::mutex mutex_;
  ResendWindow window_;
  lcm::Subscription* sub_ = nullptr;
  std::int64_t bad_ = 0;
  std::atomic<bool> stop_{false};
  std::thread thread_;
};

template <class G>
int publish(const PublishRun& run, const PoseGraph<G>& graph) {
  const long total = static_cast<long>(graph.edges.size());
  if (run.skip > total)
    throw UsageError("--skip " + std::to_string(run.skip) + " exceeds the " +
                     std::to_string(total) + " edges");
  StreamSelection selection;
  std::vector<StreamMessage<G>> messages =
      streamMessages(graph, run.sender, run.skip, run.count, &selection);
  if (!run.edge_choices.empty()) {  // edge_t's trust and kernel, per edge
    const EdgeChoices choices = readEdgeChoicesFile(run.edge_choices);
    checkEdgeChoices(choices, graph, run.edge_choices);
    for (StreamMessage<G>& m : messages) {
      if (m.is_prior) continue;
      const EdgeChoice c = edgeChoice(choices, m.edge.from, m.edge.to);
      m.edge.trust = c.trust;
      m.edge.kernel = c.kernel;
    }
  }
  const long end = static_cast<long>(selection.last_seq);
  const size_t n = static_cast<size_t>(selection.edges);

  lcm::LCM lcm(run.bus.url);
  if (!lcm.good()) throw std::runtime_error("cannot open LCM at '" + run.bus.url + "'");
  serve::tuneLcmTransport(lcm, run.bus.url);
  const serve::Channels channels = serve::Channels::withPrefix(run.bus.prefix);
  const std::unique_ptr<serve::BusAuth> auth =
      run.keys.empty() ? nullptr : std::make_unique<serve::BusAuth>(run.keys);
  // The listener has its own instance: liblcm 1.3 delays what an instance receives while
  // another thread publishes on it.
  std::unique_ptr<lcm::LCM> listen_lcm;
  std::unique_ptr<Listener> listener;
  if (run.wait || run.wait_ready) {
    listen_lcm = std::make_unique<lcm::LCM>(run.bus.url);
    if (!listen_lcm->good()) throw std::runtime_error("cannot open LCM at '" + run.bus.url + "'");
    serve::tuneLcmTransport(*listen_lcm, run.bus.url);
    listener =
        std::make_unique<Listener>(*listen_lcm, channels, run.sender, n, run.skip + 1, auth.get());
  }
  BusPublisher bus(lcm, auth.get());
  std::unique_ptr<Resender> resender;
  if (run.resend_window > 0) {
    resender =
        std::make_unique<Resender>(run.bus.url, channels, run.sender,
                                   static_cast<std::size_t>(run.resend_window), auth.get(), bus);
  }
  if (run.wait_ready && !listener->waitStatus(run.timeout_s)) {
    std::cerr << "arbor publish: no status from a server on " << channels.status << " within "
              << run.timeout_s << " s\n";
    return 1;
  }

  // --rate paces the edges; a prior goes out right after the edge it follows.
  const auto start = Clock::now();
  size_t k = 0;                 // edges sent
  std::int64_t last_prior = 0;  // the last prior's seq
  for (const StreamMessage<G>& m : messages) {
    if (!m.is_prior && run.rate > 0)
      std::this_thread::sleep_until(start + std::chrono::duration_cast<Clock::duration>(
                                                std::chrono::duration<double>(k / run.rate)));
    const auto bytes = encodeStreamMessage(m, serve::nowMicros());
    if (!m.is_prior && listener) listener->sent(k);
    const std::string& channel = m.is_prior ? channels.priors : channels.edges;
    const std::int64_t seq =
        m.is_prior ? std::visit([](const auto& p) { return p.seq; }, m.prior) : m.edge.seq;
    if (m.is_prior) last_prior = seq;
    if (resender) resender->sent(m.is_prior, seq, channel, bytes);
    if (bus.publish(channel, bytes) != 0) {
      throw std::runtime_error(std::string("LCM publish failed at ") +
                               (m.is_prior ? "prior" : "edge") + " seq " + std::to_string(seq));
    }
    if (!m.is_prior) ++k;
  }
  const double publish_s = std::chrono::duration<double>(Clock::now() - start).count();
  bool complete = true;
  bool acknowledged = true;
  if (resender)
    acknowledged = resender->waitAcknowledged(n > 0 ? end : 0, last_prior, run.timeout_s);
  if (run.wait && n > 0) complete = listener->waitCovered(end, run.timeout_s);
  const double total_s = std::chrono::duration<double>(Clock::now() - start).count();
  std::vector<double> latencies = listener ? listener->latencies() : std::vector<double>();
  const LatencySummary lat = summarizeLatency(latencies);
  if (run.json) {
    nlohmann::json j = {{"file", run.file},
                        {"sent", n},
                        {"priors_sent", selection.priors},
                        {"first_seq", run.skip + 1},
                        {"last_seq", end},
                        {"sender", run.sender},
                        {"publish_s", publish_s},
                        {"total_s", total_s},
                        {"edges_per_s", publish_s > 0 ? n / publish_s : 0.0}};
    if (resender) {
      const ResendWindow::Counts c = resender->counts();
      j["resend"] = {{"window", run.resend_window},  {"requests", c.requests},
                     {"resent", c.resent},           {"window_answers", c.window_answers},
                     {"unavailable", c.unavailable}, {"acknowledged", acknowledged}};
    }
    if (run.wait) {
      j["acknowledged"] = latencies.size();
      j["complete"] = complete;
      j["latency_ms"] = {{"p50", lat.p50}, {"p99", lat.p99}, {"max", lat.max}};
    }
    std::cout << j.dump() << std::endl;
  } else {
    std::cout << std::setprecision(4) << "sent          " << n << " edges (seq " << run.skip + 1
              << ".." << end << ", sender " << run.sender << ")";
    if (selection.priors > 0) std::cout << " and " << selection.priors << " priors";
    std::cout << " in " << publish_s << " s\n";
    if (run.wait) {
      std::cout << "estimated     " << latencies.size() << " of " << n << " edges, " << total_s
                << " s in all\n"
                << "latency ms    p50 " << lat.p50 << "  p99 " << lat.p99 << "  max " << lat.max
                << " (publish -> estimate received)\n";
    }
  }
  if (resender && !run.json) {
    const ResendWindow::Counts c = resender->counts();
    std::cout << "resent        " << c.resent << " messages for " << c.requests << " requests; "
              << c.unavailable << " asked for and no longer held\n";
  }
  if (!acknowledged) {
    std::cerr << "arbor publish: the server did not acknowledge every message within "
              << run.timeout_s << " s (--resend-window)\n";
    return 1;
  }
  if (!complete) {
    std::cerr << "arbor publish: no estimate covering seq " << end << " within " << run.timeout_s
              << " s\n";
    return 1;
  }
  return 0;
}

}  // namespace

namespace {

using P = PublishOptions;

constexpr Condition kAny{"a number", [](double) { return true; }};
constexpr Condition kPositive{"> 0", [](double x) { return x > 0; }};
constexpr Condition kNonNegative{">= 0", [](double x) { return x >= 0; }};

const char* const kStream = "Stream";
const char* const kWait = "Waiting and output";

// --rate: no default of its own (none is a burst).
OptionSpec<P> rateOption() {
  OptionSpec<P> spec = numberOption<P>(
      "rate", Tier::kCommon, kStream, "HZ",
      "edges per second (priors go with their edges); default: --burst",
      [](auto& o) -> auto& { return o.rate; }, kPositive);
  spec.get = [](const P& o) -> std::optional<std::string> {
    if (o.rate > 0) return option_detail::text(o.rate);
    return std::nullopt;
  };
  return spec;
}

OptionTable<P> makePublishTable() {
  constexpr Tier kCommon = Tier::kCommon, kAdvanced = Tier::kAdvanced;
  return {
      rateOption(),
      switchOption<P>(
          "burst", kCommon, kStream, "as fast as possible (the default)",
          [](auto& o) -> auto& { return o.burst; }, true),
      numberOption<P>(
          "count", kCommon, kStream, "N", "publish N edges (-1: all)",
          [](auto& o) -> auto& { return o.count; },
          Condition{">= 0 (or -1: all)", [](double x) { return x >= -1; }}),
      numberOption<P>(
          "skip", kAdvanced, kStream, "K", "start after the first K edges",
          [](auto& o) -> auto& { return o.skip; }, kNonNegative),
      numberOption<P>(
          "sender", kAdvanced, kStream, "ID", "sender id",
          [](auto& o) -> auto& { return o.sender; }, kAny),
      textOption<P>(
          "edge-choices", kAdvanced, kStream, "FILE",
          "per-edge trust and kernel into edge_t, 'FROM TO default|trusted|robust "
          "[KERNEL]' a line (docs/files.md)",
          [](auto& o) -> auto& { return o.edge_choices; }),
      informationOption<P>(
          kAdvanced, kStream, [](auto& o) -> auto& { return o.read.information; }),
      numberOption<P>(
          "resend-window", kAdvanced, kStream, "N",
          "keep the last N messages per stream and send again what the server reports missing "
          "(ARBOR_RESEND); then wait until it acknowledges every message (--timeout). 0: off",
          [](auto& o) -> auto& { return o.resend_window; },
          Condition{"in 0..16777216", [](double x) { return x >= 0 && x <= (1L << 24); }}),
      switchOption<P>(
          "wait", kCommon, kWait,
          "wait for the estimate covering the last edge; print publish -> estimate latency",
          [](auto& o) -> auto& { return o.wait; }, true),
      switchOption<P>(
          "wait-ready", kCommon, kWait,
          "before publishing, wait for a status message from the server",
          [](auto& o) -> auto& { return o.wait_ready; }, true),
      numberOption<P>(
          "timeout", kCommon, kWait, "S", "seconds for --wait, --wait-ready and --resend-window",
          [](auto& o) -> auto& { return o.timeout_s; }, kPositive),
      switchOption<P>(
          "json", kCommon, kWait, "print one JSON object", [](auto& o) -> auto& { return o.json; },
          true),
  };
}

FlagSet publishFlagSet(std::string* file) {
  FlagSet flags("arbor publish FILE [options]   (FILE: g2o or TORO)",
                {"arbor publish data/sphere_3d.g2o --lcm-url tcpq://127.0.0.1:7700 --rate 100",
                 "arbor publish map.g2o --key deploy.key --wait-ready --wait --json"});
  flags.positional("file", po::value(file)->required());
  flags.add(busClientOptionTable());
  flags.add(publishOptionTable());
  return flags;
}

}  // namespace

const OptionTable<PublishOptions>& publishOptionTable() {
  static const OptionTable<PublishOptions> table = makePublishTable();
  return table;
}

std::vector<FlagInfo> publishFlags() {
  std::string file;
  return publishFlagSet(&file).flags();
}

std::optional<PublishOptions> parsePublishCommandLine(const std::vector<std::string>& args) {
  PublishOptions run;
  const FlagSet flags = publishFlagSet(&run.file);
  const std::optional<po::variables_map> parsed = flags.parse(args);
  if (!parsed) return std::nullopt;
  readOptions(busClientOptionTable(), *parsed, &run.bus);
  readOptions(publishOptionTable(), *parsed, &run);
  if (run.burst && run.rate > 0) throw UsageError("--rate and --burst exclude each other");
  return run;
}

int publishCommand(const std::vector<std::string>& args) {
  const std::optional<PublishOptions> options = parsePublishCommandLine(args);
  if (!options) return 0;
  PublishRun run;
  static_cast<PublishOptions&>(run) = *options;
  run.keys = readBusKeyFlag(run.bus.key_file);  // before anything is read or opened
  const AnyPoseGraph any = readGraphFile(run.file, run.read);
  return std::visit([&](const auto& graph) { return publish(run, graph); }, any);
}

}  // namespace arbor::cli
