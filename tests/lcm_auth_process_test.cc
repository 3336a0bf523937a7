// The authenticated bus across processes (docs/lcm.md, "An authenticated bus"): `arbor serve
// --key`, `arbor publish --key` and `arbor command --key` over tcpq:// through Debian's LCM hub
// (java lcm.lcm.TCPService on a free loopback port of the test's own). A keyed stream is applied
// whole and a keyed covariance command answered; an unkeyed and a wrong-key publisher's edges
// and an unkeyed command are refused, counted in serve's --json, and none of them is applied; a
// key file other users can read is refused with the reason. Every wait is on a condition (a log
// line, a process exit) with a generous timeout as a failure guard; every process started is
// stopped, pass or fail.
#include <chrono>
#include <filesystem>
#include <fstream>
#include <functional>
#include <memory>
#include <string>
#include <thread>
#include <vector>

#include <gtest/gtest.h>
#include <sys/stat.h>
#include <nlohmann/json.hpp>

#include "process_support.h"

namespace arbor {
namespace {

namespace fs = std::filesystem;
using testing::Process;
using testing::RunResult;
using Clock = std::chrono::steady_clock;

constexpr double kGuard = 60;  // seconds: a failure guard, never a pacing

using testing::waitUntil;  // its default guard, 60 s, is kGuard

class LcmAuthProcess : public ::testing::Test {
 protected:
  void SetUp() override {
    dir_ = fs::temp_directory_path() / ("arbor_lcm_auth_" + std::to_string(getpid()));
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
  RunResult arbor(std::vector<std::string> args, const std::string& stem, double timeout = kGuard) {
    args.insert(args.begin(), ARBOR_EXE);
    return testing::run(args, path(stem), timeout);
  }
  void startHub() {
    hub_ = std::make_unique<Process>(
        std::vector<std::string>{"java", "-cp", "/usr/share/java/lcm.jar", "lcm.lcm.TCPService",
                                 std::to_string(port_)},
        path("hub.out"), path("hub.err"));
    ASSERT_TRUE(hub_->started());
    ASSERT_TRUE(waitUntil([&] { return testing::portOpen(port_); }))
        << "the LCM hub (java lcm.lcm.TCPService) did not start: " << hub_->err();
  }
  fs::path dir_;
  int port_ = 0;
  std::unique_ptr<Process> hub_;
};

TEST_F(LcmAuthProcess, OnlyKeyedMessagesAreAppliedAndAnsweredAcrossProcesses) {
  const std::string key = path("bus.key"), other = path("other.key");
  RunResult r = arbor({"keygen", key}, "keygen1");
  ASSERT_EQ(r.status, 0) << r.err;
  EXPECT_NE(r.out.find("written to " + key), std::string::npos) << r.out;
  r = arbor({"keygen", other}, "keygen2");
  ASSERT_EQ(r.status, 0);
  const std::string other_id = r.out.substr(4, 16);  // "key ID written to FILE"
  EXPECT_EQ(arbor({"keygen", key}, "keygen3").status, 1) << "never over an existing key";

  // A key file other users can read: refused by every program, naming the file and the fix.
  const std::string open_key = path("open.key");
  fs::copy_file(key, open_key);
  ::chmod(open_key.c_str(), 0644);
  r = arbor({"serve", "--lcm-url", url(), "--key", open_key}, "serve_open_key");
  EXPECT_EQ(r.status, 1);
  EXPECT_NE(r.err.find("key file " + open_key + ": mode 0644"), std::string::npos) << r.err;
  EXPECT_NE(r.err.find("chmod 600"), std::string::npos) << r.err;
  const std::string graph = path("manhattan.g2o");
  ASSERT_EQ(
      arbor({"generate", "manhattan", "--poses", "300", "--grid", "5", "--seed", "4", "-o", graph},
            "generate")
          .status,
      0);
  r = arbor({"publish", graph, "--lcm-url", url(), "--key", open_key}, "publish_open_key");
  EXPECT_EQ(r.status, 1);
  EXPECT_NE(r.err.find("chmod 600"), std::string::npos) << r.err;
  r = arbor({"command", "disable", "1", "2", "--lcm-url", url(), "--key", path("absent.key")},
            "command_absent_key");
  EXPECT_EQ(r.status, 1);
  EXPECT_NE(r.err.find("key file " + path("absent.key") + ": No such file"), std::string::npos)
      << r.err;
  startHub();
  Process serve({ARBOR_EXE, "serve", "--lcm-url", url(), "--key", key, "--json", "--status-period",
                 "0.2", "--no-refine"},
                path("serve.out"), path("serve.err"));
  ASSERT_TRUE(waitUntil([&] { return serve.err().find("receive link up") != std::string::npos; }))
      << serve.err();

  // Unkeyed and wrong-key publishers: 20 edges each, under senders of their own.
  r = arbor({"publish", graph, "--lcm-url", url(), "--count", "20", "--sender", "7"}, "unkeyed");
  EXPECT_EQ(r.status, 0) << r.err;
  r = arbor(
      {"publish", graph, "--lcm-url", url(), "--count", "20", "--sender", "8", "--key", other},
      "wrong_key");
  EXPECT_EQ(r.status, 0) << r.err;
  ASSERT_TRUE(waitUntil([&] {
    const std::string err = serve.err();
    return err.find("auth unsigned") != std::string::npos &&
           err.find("auth unknown key") != std::string::npos;
  })) << serve.err();

  // The keyed front end: every edge, acknowledged by a keyed estimate.
  r = arbor({"publish", graph, "--lcm-url", url(), "--key", key, "--wait", "--wait-ready",
             "--timeout", "60", "--json"},
            "keyed", 2 * kGuard);
  ASSERT_EQ(r.status, 0) << r.err;
  const nlohmann::json published = nlohmann::json::parse(r.out);
  EXPECT_TRUE(published.at("complete").get<bool>());
  const int edges = published.at("sent").get<int>();

  // A keyed command is answered; an unkeyed one is refused and never answered.
  r = arbor({"command", "covariance", "5", "--lcm-url", url(), "--key", key, "--json"},
            "covariance");
  EXPECT_EQ(r.status, 0) << r.err;
  EXPECT_FALSE(nlohmann::json::parse(r.out).contains("error")) << r.out;
  r = arbor({"command", "covariance", "5", "--lcm-url", url(), "--timeout", "2"},
            "covariance_unkeyed");
  EXPECT_EQ(r.status, 1);

  // Rotation without a restart: the key file rewritten with the other key first, then SIGHUP;
  // a client that holds only the other key is answered.
  {
    const std::string ring = testing::readFile(other) + testing::readFile(key);
    std::ofstream(key, std::ios::trunc) << ring;
  }
  serve.signal(SIGHUP);
  ASSERT_TRUE(waitUntil([&] {
    return serve.err().find("keys reloaded: signing with key " + other_id) != std::string::npos;
  })) << serve.err();
  r = arbor({"command", "covariance", "5", "--lcm-url", url(), "--key", other, "--json"},
            "covariance_rotated");
  EXPECT_EQ(r.status, 0) << r.err;

  serve.signal(SIGTERM);
  ASSERT_EQ(serve.wait(kGuard), 0) << serve.err();
  const nlohmann::json s = nlohmann::json::parse(serve.out());
  EXPECT_EQ(s.at("received").get<int>(), edges) << "nothing refused was decoded";
  EXPECT_EQ(s.at("applied").get<int>(), edges);
  EXPECT_EQ(s.at("gaps").get<int>(), 0);
  const nlohmann::json& refused = s.at("faults").at("auth_refused");
  EXPECT_EQ(refused.at("unsigned").get<int>(), 20 + 1) << refused.dump();
  EXPECT_EQ(refused.at("unknown key").get<int>(), 20) << refused.dump();
  EXPECT_FALSE(refused.contains("mac")) << refused.dump();
  EXPECT_FALSE(refused.contains("replay")) << refused.dump();
}

}  // namespace
}  // namespace arbor
