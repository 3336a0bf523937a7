// Robots on several hosts (issue 56, item 5; docs/lcm.md, "Robots on several hosts"): three
// robots, each in a network namespace of its own with its own `arbor publish --resend-window`,
// and `arbor serve` in a fourth, joined by veth links to one bridge, udpm (ttl=1) across it.
// Robot 1's link loses 5% of its UDP datagrams each way (nftables on the bridge) and is cut for
// 10 s mid-stream (its bridge port down). tools/bench/several_hosts.sh builds the network, runs
// the processes and keeps their JSON; this test reads it: every edge of every robot applied
// exactly once, F equal to `arbor replay` of the merged file to 1e-9. The same network without
// resending loses edges (the test is not vacuous).
//
// The script runs everything inside a private parent namespace of its own (network, pid and
// mount): its only links are those it makes, nothing reaches the machine's network, and when it
// ends (or is killed) the kernel ends every process in it and the namespaces and links go too.
// Where the machine allows no network namespaces the script exits 77 and the test skips.
#include <filesystem>
#include <iostream>
#include <string>
#include <vector>

#include <gtest/gtest.h>
#include <unistd.h>
#include <nlohmann/json.hpp>

#include "arbor_slam/io/pose_graph_file.h"
#include "private_network.h"
#include "process_support.h"

namespace arbor {
namespace {

namespace fs = std::filesystem;
using testing::RunResult;

constexpr int kSkip = 77;  // the script's exit when namespaces are not allowed

int edgesOf(const std::string& file) {
  return std::visit([](const auto& g) { return g.numEdges(); }, readPoseGraphFile(file));
}

nlohmann::json readJson(const std::string& file) {
  const std::string text = testing::readFile(file);
  try {
    return nlohmann::json::parse(text);
  } catch (const std::exception&) {
    ADD_FAILURE() << file << " holds no JSON: " << text;
    return nlohmann::json::object();
  }
}

class SeveralHosts : public ::testing::Test {
 protected:
  void SetUp() override {
    dir_ = fs::temp_directory_path() /
           ("arbor_lcm_hosts_" + std::to_string(getpid()) + "_" +
            ::testing::UnitTest::GetInstance()->current_test_info()->name());
    fs::remove_all(dir_);
    fs::create_directories(dir_);
    interfaces_ = testing::PrivateNetwork::interfaces();
  }
  void TearDown() override {
    // Nothing the script made is left in the test's own namespace.
    EXPECT_EQ(testing::PrivateNetwork::interfaces(), interfaces_);
    std::error_code ec;
    fs::remove_all(dir_, ec);
  }
  std::string path(const std::string& name) const { return (dir_ / name).string(); }

  // Runs the script with `env` (VAR=value); false when it skipped.
  bool runHosts(const std::vector<std::string>& env) {
    std::vector<std::string> argv = {"env", std::string("ARBOR=") + ARBOR_EXE,
                                     "OUT=" + dir_.string(), "GUARD=120"};
    argv.insert(argv.end(), env.begin(), env.end());
    argv.push_back("bash");
    argv.push_back(std::string(ARBOR_SOURCE_DIR) + "/tools/bench/several_hosts.sh");
    const RunResult r = testing::run(argv, path("several_hosts"), 150);
    if (r.status == kSkip) {
      skipped_ = r.err;
      return false;
    }
    EXPECT_EQ(r.status, 0) << r.err << r.out;
    std::cout << r.out;
    return r.status == 0;
  }
  std::string run1(const std::string& name) const { return (dir_ / "run1" / name).string(); }
  double replayF(const std::string& file) {
    const RunResult r = testing::run({ARBOR_EXE, "replay", file, "--json"}, path("replay"));
    EXPECT_EQ(r.status, 0) << r.err;
    return nlohmann::json::parse(r.out).at("F_final").get<double>();
  }

  fs::path dir_;
  std::vector<std::string> interfaces_;
  std::string skipped_;
};

// Issue 56's goal: 5% loss and a 10-s outage on one of three hosts; every edge of every robot
// applied exactly once, F equal to `arbor replay` of the merged file (1e-9 relative).
TEST_F(SeveralHosts, FivePercentLossAndATenSecondCutOnOneOfThreeHostsLoseNothing) {
  if (!runHosts({"POSES=1500 700 700", "RATE=100", "LOSS=5", "OUTAGE_AT=5", "OUTAGE_S=10"})) {
    if (!skipped_.empty()) GTEST_SKIP() << skipped_;
    return;
  }
  int edges = 0;
  std::vector<nlohmann::json> published;
  for (int robot = 1; robot <= 3; ++robot) {
    const int own = edgesOf(run1("robot" + std::to_string(robot) + ".g2o"));
    edges += own;
    published.push_back(readJson(run1("publish" + std::to_string(robot) + ".json")));
    const nlohmann::json& p = published.back();
    EXPECT_EQ(p.at("sent").get<int>(), own) << p.dump();
    EXPECT_TRUE(p.at("resend").at("acknowledged").get<bool>()) << p.dump();
  }
  const nlohmann::json link = readJson(run1("link.json"));
  const nlohmann::json j = readJson(run1("serve.json"));
  // Robot 1's link really lost datagrams both ways, and ~10 s of its stream in the cut.
  EXPECT_GT(link.at("out").get<int>(), 0) << link.dump();
  EXPECT_GT(link.at("in").get<int>(), 0) << link.dump();
  EXPECT_GT(link.at("outage_dropped_out").get<int>(), 500) << link.dump();
  EXPECT_GT(published[0].at("resend").at("resent").get<int>(), 500) << published[0].dump();
  // Every edge applied, exactly once.
  EXPECT_EQ(j.at("accepted").get<int>(), edges) << j.dump();
  EXPECT_EQ(j.at("applied").get<int>(), edges) << j.dump();
  EXPECT_EQ(j.at("rejected").get<int>(), 0) << j.dump();
  EXPECT_EQ(j.at("gaps").get<int>(), 0) << j.dump();
  EXPECT_EQ(j.at("loss_recovery").at("given_up").get<int>(), 0) << j.dump();
  EXPECT_EQ(j.at("loss_recovery").at("late").get<int>(), 0) << j.dump();
  EXPECT_EQ(j.at("loss_recovery").at("held").get<int>(), 0) << j.dump();
  EXPECT_EQ(j.at("received").get<int>(),
            j.at("accepted").get<int>() + j.at("duplicates").get<int>())
      << j.dump();
  EXPECT_EQ(j.at("components").get<int>(), 3) << j.dump();
  const double F = replayF(run1("merged.g2o"));
  EXPECT_NEAR(j.at("F_final").get<double>(), F, 1e-9 * F);
  std::cout << "several hosts: " << edges << " edges; robot 1's link " << link.dump()
            << "; robot 1 " << published[0].at("resend").dump() << "; robots 2, 3 resent "
            << published[1].at("resend").at("resent") << ", "
            << published[2].at("resend").at("resent") << "; serve duplicates " << j.at("duplicates")
            << ", loss_recovery " << j.at("loss_recovery").dump() << "; F " << j.at("F_final")
            << " vs replay " << F << "\n";
}

// The same network without resending: robot 1's lost edges stay lost (the test above is not
// vacuous).
TEST_F(SeveralHosts, WithoutResendTheSameNetworkLosesEdges) {
  if (!runHosts(
          {"POSES=600 300 300", "RATE=100", "LOSS=5", "OUTAGE_AT=2", "OUTAGE_S=2", "RESEND=0"})) {
    if (!skipped_.empty()) GTEST_SKIP() << skipped_;
    return;
  }
  int edges = 0;
  for (int robot = 1; robot <= 3; ++robot)
    edges += edgesOf(run1("robot" + std::to_string(robot) + ".g2o"));
  const nlohmann::json link = readJson(run1("link.json"));
  const nlohmann::json j = readJson(run1("serve.json"));
  EXPECT_GT(link.at("out").get<int>() + link.at("outage_dropped_out").get<int>(), 0) << link.dump();
  EXPECT_LT(j.at("applied").get<int>(), edges) << j.dump();
  EXPECT_GT(j.at("loss_recovery").at("given_up").get<int>(), 0) << j.dump();
  std::cout << "without resend: " << j.at("applied") << " of " << edges << " edges applied, "
            << "given up " << j.at("loss_recovery").at("given_up") << "\n";
}

}  // namespace
}  // namespace arbor
