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
#include "arbor_slam/tools/cli/publish_stream.h"
#include "arbor_slam/tools/serve/lcm_tuning.h"
#include "arbor_slam/tools/serve/serve_service.h"

namespace arbor::cli {
namespace {

namespace po = boost::program_options;
using Clock = std::chrono::steady_clock;

struct PublishRun {
  std::string file, url, prefix;
  double rate = 0;  // 0: burst
  std::int64_t sender = 1;
  long skip = 0, count = -1;
  bool wait = false, wait_ready = false, json = false;
  double timeout_s = 60;
  ReadOptions read;
  std::string edge_choices;  // --edge-choices FILE (io/edge_choice_file.h)
  std::string key_file;      // --key FILE (tools/cli/bus_key_flag.h)
  serve::BusKeyring keys;    // its keys (none without --key)
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

  lcm::LCM lcm(run.url);
  if (!lcm.good()) throw std::runtime_error("cannot open LCM at '" + run.url + "'");
  serve::tuneLcmTransport(lcm, run.url);
  const serve::Channels channels = serve::Channels::withPrefix(run.prefix);
  const std::unique_ptr<serve::BusAuth> auth =
      run.keys.empty() ? nullptr : std::make_unique<serve::BusAuth>(run.keys);
  // The listener has its own instance: liblcm 1.3 delays what an instance receives while
  // another thread publishes on it.
  std::unique_ptr<lcm::LCM> listen_lcm;
  std::unique_ptr<Listener> listener;
  if (run.wait || run.wait_ready) {
    listen_lcm = std::make_unique<lcm::LCM>(run.url);
    if (!listen_lcm->good()) throw std::runtime_error("cannot open LCM at '" + run.url + "'");
    serve::tuneLcmTransport(*listen_lcm, run.url);
    listener =
        std::make_unique<Listener>(*listen_lcm, channels, run.sender, n, run.skip + 1, auth.get());
  }
  if (run.wait_ready && !listener->waitStatus(run.timeout_s)) {
    std::cerr << "arbor publish: no status from a server on " << channels.status << " within "
              << run.timeout_s << " s\n";
    return 1;
  }

  // --rate paces the edges; a prior goes out right after the edge it follows.
  const auto start = Clock::now();
  size_t k = 0;  // edges sent
  for (const StreamMessage<G>& m : messages) {
    if (!m.is_prior && run.rate > 0)
      std::this_thread::sleep_until(start + std::chrono::duration_cast<Clock::duration>(
                                                std::chrono::duration<double>(k / run.rate)));
    const auto bytes = encodeStreamMessage(m, serve::nowMicros());
    if (!m.is_prior && listener) listener->sent(k);
    const std::string& channel = m.is_prior ? channels.priors : channels.edges;
    if (publishOnBus(lcm, auth.get(), channel, bytes) != 0) {
      const std::int64_t seq =
          m.is_prior ? std::visit([](const auto& p) { return p.seq; }, m.prior) : m.edge.seq;
      throw std::runtime_error(std::string("LCM publish failed at ") +
                               (m.is_prior ? "prior" : "edge") + " seq " + std::to_string(seq));
    }
    if (!m.is_prior) ++k;
  }
  const double publish_s = std::chrono::duration<double>(Clock::now() - start).count();
  bool complete = true;
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
  if (!complete) {
    std::cerr << "arbor publish: no estimate covering seq " << end << " within " << run.timeout_s
              << " s\n";
    return 1;
  }
  return 0;
}

}  // namespace

int publishCommand(const std::vector<std::string>& args) {
  PublishRun run;
  bool burst = false;
  std::string information = "refuse";
  po::options_description desc("arbor publish FILE [options]");
  desc.add_options()("help,h", "show this help")("file", po::value(&run.file)->required(),
                                                 "g2o or TORO file")(
      "lcm-url", po::value(&run.url), "LCM provider URL (default: LCM's default)")(
      "channel-prefix", po::value(&run.prefix), "prefix of the ARBOR_* channels")(
      "rate", po::value(&run.rate), "edges per second (priors go with their edges)")(
      "burst", po::bool_switch(&burst), "as fast as possible (the default)")(
      "sender", po::value(&run.sender)->default_value(1), "sender id")(
      "skip", po::value(&run.skip)->default_value(0), "start after the first K edges")(
      "count", po::value(&run.count)->default_value(-1), "publish N edges (-1: all)")(
      "wait", po::bool_switch(&run.wait),
      "wait for the estimate covering the last edge; print publish -> estimate latency")(
      "wait-ready", po::bool_switch(&run.wait_ready),
      "before publishing, wait for a status message from the server")(
      "timeout", po::value(&run.timeout_s)->default_value(60), "seconds for --wait/--wait-ready")(
      "information", po::value(&information)->default_value("refuse"),
      "refuse | repair | isotropic (information matrices that are not positive definite)")(
      "json", po::bool_switch(&run.json), "print one JSON object")(
      "edge-choices", po::value(&run.edge_choices),
      "per-edge trust and kernel into edge_t, 'FROM TO default|trusted|robust [KERNEL]' a line "
      "(docs/files.md)");
  addBusKeyFlag(desc, &run.key_file);
  po::positional_options_description positional;
  positional.add("file", 1);
  if (helpRequested(args, desc)) return 0;
  const auto vm = parseArguments(args, desc, positional);
  if (burst && vm.count("rate")) throw UsageError("--rate and --burst exclude each other");
  if (vm.count("rate") && !(run.rate > 0)) throw UsageError("--rate must be > 0");
  if (run.skip < 0) throw UsageError("--skip must be >= 0");
  if (run.count < -1) throw UsageError("--count must be >= 0 (or -1: all)");
  if (!(run.timeout_s > 0)) throw UsageError("--timeout must be > 0");
  run.read.information = parseInformationPolicy(information);
  run.keys = readBusKeyFlag(run.key_file);  // before anything is read or opened
  const AnyPoseGraph any = readGraphFile(run.file, run.read);
  return std::visit([&](const auto& graph) { return publish(run, graph); }, any);
}

}  // namespace arbor::cli
