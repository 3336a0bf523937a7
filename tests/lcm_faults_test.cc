// `arbor serve` over tcpq:// when its transport fails: Debian's LCM hub (java lcm.lcm.TCPService
// on loopback, a port of each test's own) absent at start, killed mid-stream and restarted, and
// a "hub" that accepts the connection and never answers (liblcm's handshake has no timeout).
// The service never aborts, keeps its state, re-creates its links with backoff and resumes; every
// edge accepted before the fault is in the final estimate, which equals `arbor replay`'s; on
// SIGTERM during an outage it still writes the estimate and the journal. Every wait is on a
// condition (a log line, a file, a process exit) with a generous timeout as a failure guard.
// Every process a test starts is stopped, pass or fail.
#include <chrono>
#include <filesystem>
#include <functional>
#include <memory>
#include <string>
#include <thread>
#include <vector>

#include <gtest/gtest.h>
#include <netinet/in.h>
#include <poll.h>
#include <sys/socket.h>
#include <unistd.h>
#include <nlohmann/json.hpp>

#include <atomic>
#include <mutex>

#include "arbor_slam/io/lcm_journal.h"
#include "arbor_slam/io/lcm_messages.h"
#include "arbor_slam/io/pose_graph_file.h"
#include "process_support.h"

namespace arbor {
namespace {

namespace fs = std::filesystem;
using testing::Process;
using testing::RunResult;
using Clock = std::chrono::steady_clock;

constexpr double kGuard = 60;  // seconds: a failure guard, never a pacing

using testing::waitUntil;  // its default guard, 60 s, is kGuard

int countOf(const std::string& text, const std::string& what) {
  int n = 0;
  for (size_t at = text.find(what); at != std::string::npos; at = text.find(what, at + 1)) ++n;
  return n;
}

// The edges of a journal, in file order, by seq.
std::vector<std::int64_t> journalSeqs(const std::string& path) {
  std::vector<std::int64_t> seqs;
  for (const auto& e : readEventLog(path).events) {
    edge_t m;
    if (decodeMessage(e.data.data(), static_cast<int>(e.data.size()), &m) == MessageProblem::kNone)
      seqs.push_back(m.seq);
  }
  return seqs;
}

// A "hub" on a loopback port that accepts every connection and never writes a byte: what
// liblcm's tcpq handshake (a blocking recv() of the hub's answer) would wait on forever.
class SilentHub {
 public:
  explicit SilentHub(int port) {
    listener_ = ::socket(AF_INET, SOCK_STREAM | SOCK_CLOEXEC, 0);
    const int on = 1;
    ::setsockopt(listener_, SOL_SOCKET, SO_REUSEADDR, &on, sizeof(on));
    sockaddr_in a{};
    a.sin_family = AF_INET;
    a.sin_port = htons(static_cast<std::uint16_t>(port));
    a.sin_addr.s_addr = htonl(INADDR_LOOPBACK);
    listening_ = ::bind(listener_, reinterpret_cast<sockaddr*>(&a), sizeof(a)) == 0 &&
                 ::listen(listener_, 16) == 0;
    thread_ = std::thread([this] {
      while (!stop_) {
        pollfd p{listener_, POLLIN, 0};
        if (::poll(&p, 1, 50) <= 0) continue;
        const int fd = ::accept(listener_, nullptr, nullptr);
        if (fd < 0) continue;
        std::lock_guard<std::mutex> lock(mutex_);
        accepted_.push_back(fd);  // held open, never written to
      }
    });
  }
  ~SilentHub() {
    stop_ = true;
    thread_.join();
    const linger reset{1, 0};  // close with a reset: no TIME_WAIT to keep the port from the hub
    for (int fd : accepted_) {
      ::setsockopt(fd, SOL_SOCKET, SO_LINGER, &reset, sizeof(reset));
      ::close(fd);
    }
    ::close(listener_);
  }
  SilentHub(const SilentHub&) = delete;
  SilentHub& operator=(const SilentHub&) = delete;
  bool listening() const { return listening_; }
  size_t accepted() {
    std::lock_guard<std::mutex> lock(mutex_);
    return accepted_.size();
  }

 private:
  int listener_ = -1;
  bool listening_ = false;
  std::atomic<bool> stop_{false};
  std::mutex mutex_;
  std::vector<int> accepted_;
  std::thread thread_;
};

int edgesOf(const std::string& file) {
  return std::visit([](const auto& g) { return g.numEdges(); }, readPoseGraphFile(file));
}

class LcmFaults : public ::testing::Test {
 protected:
  void SetUp() override {
    dir_ = fs::temp_directory_path() /
           ("arbor_lcm_faults_" + std::to_string(getpid()) + "_" +
            ::testing::UnitTest::GetInstance()->current_test_info()->name());
    fs::remove_all(dir_);
    fs::create_directories(dir_);
    port_ = testing::freePort();
  }
  void TearDown() override {
    hub_.reset();  // SIGKILL + reap
    std::error_code ec;
    fs::remove_all(dir_, ec);
  }
  std::string path(const std::string& name) const { return (dir_ / name).string(); }
  std::string url() const { return "tcpq://127.0.0.1:" + std::to_string(port_); }

  // Starts the hub on this test's port and waits until it accepts connections.
  void startHub() {
    const std::string stem = path("hub" + std::to_string(++hubs_));
    hub_ = std::make_unique<Process>(
        std::vector<std::string>{"java", "-cp", "/usr/share/java/lcm.jar", "lcm.lcm.TCPService",
                                 std::to_string(port_)},
        stem + ".out", stem + ".err");
    ASSERT_TRUE(hub_->started());
    ASSERT_TRUE(waitUntil([&] { return testing::portOpen(port_); }))
        << "the LCM hub (java lcm.lcm.TCPService) did not start: " << hub_->err();
  }
  void killHub() {
    hub_->signal(SIGKILL);
    EXPECT_EQ(hub_->wait(kGuard), -SIGKILL);
    hub_.reset();
  }

  std::unique_ptr<Process> startServe(std::vector<std::string> extra) {
    std::vector<std::string> argv = {ARBOR_EXE, "serve",           "--lcm-url", url(),
                                     "--json",  "--status-period", "0.2"};
    // F is compared with replay's: the exit refinement runs to convergence whatever the load.
    argv.insert(argv.end(), {"--exit-refine-budget", "none"});
    argv.insert(argv.end(), extra.begin(), extra.end());
    return std::make_unique<Process>(argv, path("serve.out"), path("serve.err"));
  }
  // The receive link is subscribed at the hub for the `n`th time (its probe came back).
  static bool waitLinkUp(Process& serve, int n) {
    return waitUntil([&] { return countOf(serve.err(), "receive link up") >= n; });
  }
  static bool waitLinkDown(Process& serve, int n) {
    return waitUntil([&] { return countOf(serve.err(), "receive link down") >= n; });
  }

  std::string graph() {
    const std::string file = path("manhattan.g2o");
    const RunResult r = testing::run({ARBOR_EXE, "generate", "manhattan", "--poses", "400",
                                      "--grid", "5", "--seed", "2", "-o", file},
                                     path("generate"));
    EXPECT_EQ(r.status, 0) << r.err;
    return file;
  }
  double replayF(const std::string& file) {
    const RunResult r = testing::run({ARBOR_EXE, "replay", file, "--json"}, path("replay"));
    EXPECT_EQ(r.status, 0) << r.err;
    return nlohmann::json::parse(r.out).at("F_final").get<double>();
  }
  RunResult publish(const std::string& file, std::vector<std::string> extra) {
    std::vector<std::string> argv = {ARBOR_EXE, "publish",      file,        "--lcm-url", url(),
                                     "--wait",  "--wait-ready", "--timeout", "60",        "--json"};
    argv.insert(argv.end(), extra.begin(), extra.end());
    return testing::run(argv, path("publish" + std::to_string(++publishes_)), 2 * kGuard);
  }
  static nlohmann::json stopServe(Process& serve) {
    serve.signal(SIGTERM);
    const int status = serve.wait(kGuard);
    EXPECT_EQ(status, 0) << "serve must exit 0, never abort: " << serve.err();
    try {
      return nlohmann::json::parse(serve.out());
    } catch (const std::exception&) {
      ADD_FAILURE() << "serve printed no JSON: " << serve.out() << serve.err();
      return nlohmann::json::object();
    }
  }

  fs::path dir_;
  int port_ = 0;
  int hubs_ = 0, publishes_ = 0;
  std::unique_ptr<Process> hub_;
};

TEST_F(LcmFaults, HubAbsentAtStartThenStartedServeResumesAndAppliesEverything) {
  const std::string file = graph();
  const int edges = edgesOf(file);
  auto serve = startServe({"--journal", path("journal")});
  ASSERT_TRUE(waitLinkDown(*serve, 1)) << serve->err();
  EXPECT_EQ(serve->wait(0), -1000) << "serve ended without its hub: " << serve->err();
  startHub();
  ASSERT_TRUE(waitLinkUp(*serve, 1)) << serve->err();
  const RunResult pub = publish(file, {});
  ASSERT_EQ(pub.status, 0) << pub.err << pub.out;
  const nlohmann::json j = stopServe(*serve);
  EXPECT_EQ(j.at("applied").get<int>(), edges);
  EXPECT_EQ(j.at("gaps").get<int>(), 0);
  EXPECT_GE(j.at("faults").at("link_outages").get<int>(), 1);
  const double F = replayF(file);
  EXPECT_NEAR(j.at("F_final").get<double>(), F, 1e-9 * F);
}

TEST_F(LcmFaults, HubKilledMidStreamAndRestartedLosesNoAcceptedEdge) {
  const std::string file = graph();
  const int edges = edgesOf(file);
  const std::string journal = path("journal");
  startHub();
  auto serve = startServe({"--journal", journal, "--fsync", "never"});
  ASSERT_TRUE(waitLinkUp(*serve, 1)) << serve->err();
  {
    // Streams at 300/s (no --wait: nothing of it listens, so the hub's death only fails its
    // publishes); the hub dies under it once a third of the stream is in the journal.
    std::thread publisher([&] {
      testing::run({ARBOR_EXE, "publish", file, "--lcm-url", url(), "--rate", "300"},
                   path("publish_stream"), 2 * kGuard);
    });
    EXPECT_TRUE(waitUntil([&] {
      return journalSeqs(journal + "/journal.lcmlog").size() >= static_cast<size_t>(edges / 3);
    }));
    killHub();
    publisher.join();  // ends before the hub is back: nothing of it arrives later
  }
  ASSERT_TRUE(waitLinkDown(*serve, 1)) << serve->err();
  EXPECT_EQ(serve->wait(0), -1000) << "serve ended with its hub: " << serve->err();
  // What was accepted before the fault: seq 1..K, in order.
  const std::vector<std::int64_t> seqs = journalSeqs(journal + "/journal.lcmlog");
  ASSERT_FALSE(seqs.empty());
  for (size_t k = 0; k < seqs.size(); ++k) ASSERT_EQ(seqs[k], static_cast<std::int64_t>(k) + 1);
  const int accepted = static_cast<int>(seqs.size());
  startHub();
  ASSERT_TRUE(waitLinkUp(*serve, 2)) << serve->err();
  if (accepted < edges) {
    const RunResult pub = publish(file, {"--skip", std::to_string(accepted)});
    ASSERT_EQ(pub.status, 0) << pub.err << pub.out;
  }
  const nlohmann::json j = stopServe(*serve);
  EXPECT_EQ(j.at("applied").get<int>(), edges);
  EXPECT_EQ(j.at("gaps").get<int>(), 0);
  EXPECT_EQ(j.at("rejected").get<int>(), 0);
  EXPECT_GE(j.at("faults").at("link_outages").get<int>(), 1);
  const double F = replayF(file);
  EXPECT_NEAR(j.at("F_final").get<double>(), F, 1e-9 * F);
}

TEST_F(LcmFaults, SigtermDuringAnOutageStillWritesTheEstimateAndTheJournal) {
  const std::string file = graph();
  const int half = edgesOf(file) / 2;
  const std::string journal = path("journal"), out = path("served.g2o");
  startHub();
  auto serve = startServe({"--journal", journal, "-o", out});
  ASSERT_TRUE(waitLinkUp(*serve, 1)) << serve->err();
  const RunResult pub = publish(file, {"--count", std::to_string(half)});
  ASSERT_EQ(pub.status, 0) << pub.err << pub.out;
  killHub();
  ASSERT_TRUE(waitLinkDown(*serve, 1)) << serve->err();
  const nlohmann::json j = stopServe(*serve);
  EXPECT_EQ(j.at("applied").get<int>(), half);
  EXPECT_EQ(static_cast<int>(journalSeqs(journal + "/journal.lcmlog").size()), half);
  ASSERT_TRUE(fs::exists(out)) << serve->err();
  EXPECT_EQ(edgesOf(out), half);
}

TEST_F(LcmFaults, HubThatNeverAnswersTheHandshakeNeitherHangsServeNorKeepsItFromRecovering) {
  const std::string file = graph();
  const int edges = edgesOf(file);
  auto silent = std::make_unique<SilentHub>(port_);
  ASSERT_TRUE(silent->listening());
  auto serve = startServe({"--journal", path("journal")});
  // Down with the reason, never stuck in liblcm's handshake: it goes on checking the hub.
  ASSERT_TRUE(waitUntil([&] {
    return serve->err().find("did not answer LCM's handshake") != std::string::npos;
  })) << serve->err();
  ASSERT_TRUE(waitLinkDown(*serve, 1)) << serve->err();
  ASSERT_TRUE(waitUntil([&] { return silent->accepted() >= 3; })) << serve->err();
  EXPECT_EQ(serve->wait(0), -1000) << "serve ended at a silent hub: " << serve->err();
  silent.reset();
  startHub();
  ASSERT_TRUE(waitLinkUp(*serve, 1)) << serve->err();
  const RunResult pub = publish(file, {});
  ASSERT_EQ(pub.status, 0) << pub.err << pub.out;
  const nlohmann::json j = stopServe(*serve);
  EXPECT_EQ(j.at("applied").get<int>(), edges);
  EXPECT_EQ(j.at("gaps").get<int>(), 0);
  const double F = replayF(file);
  EXPECT_NEAR(j.at("F_final").get<double>(), F, 1e-9 * F);
}

}  // namespace
}  // namespace arbor
