// `arbor serve`'s own udpm receive path (tools/serve/lcm_datagram.h, udpm_receiver.h): LCM's
// wire format checked before anything parses a datagram, fragments reassembled in a bounded
// table. In-process: each refusal reason, reassembly against liblcm's sending layout, the table's
// bounds, and 20,000 mutated datagrams. Across processes, inside a private network namespace
// (skipped, saying why, where none can be made): issue 56's 544-byte datagram — which ended
// serve with SIGSEGV inside liblcm 1.3.1 — and 3,000 mutated LC02/LC03 datagrams sent to serve's
// group, then a real stream that is applied whole (F equal to `arbor replay`'s).
#include <arpa/inet.h>
#include <netinet/in.h>
#include <sys/socket.h>
#include <unistd.h>

#include <algorithm>
#include <chrono>
#include <filesystem>
#include <fstream>
#include <iostream>
#include <map>
#include <set>
#include <sstream>
#include <string>
#include <thread>
#include <vector>

#include <gtest/gtest.h>
#include <lcm/lcm-cpp.hpp>
#include <nlohmann/json.hpp>

#include "arbor_slam/io/lcm_messages.h"
#include "arbor_slam/io/pose_graph_file.h"
#include "arbor_slam/tools/serve/lcm_datagram.h"
#include "arbor_slam/tools/serve/udpm_receiver.h"
#include "lcm_datagrams.h"
#include "private_network.h"
#include "process_support.h"

namespace arbor {
namespace {

namespace fs = std::filesystem;
using serve::DatagramLimits;
using serve::DatagramOutcome;
using serve::LcmDatagramAssembler;
using testing::Datagram;

LcmDatagramAssembler assemblerFor(const std::string& channel, DatagramLimits limits = {}) {
  return LcmDatagramAssembler(limits, [channel](const std::string& c) { return c == channel; });
}

DatagramOutcome add(LcmDatagramAssembler& a, const Datagram& d, std::uint64_t source = 1) {
  return a.add(source, d.data(), d.size());
}

std::vector<std::uint8_t> bytes(std::size_t n, std::uint32_t seed) {
  std::vector<std::uint8_t> b(n);
  for (std::size_t k = 0; k < n; ++k) b[k] = static_cast<std::uint8_t>((k * 131 + seed) % 251);
  return b;
}

TEST(LcmDatagram, AShortMessageOnAWantedChannelIsHandedOnAnotherIsSkipped) {
  LcmDatagramAssembler a = assemblerFor("EDGES");
  const auto data = bytes(300, 1);
  const Datagram d = testing::lcmDatagrams("EDGES", data, 1).at(0);
  const DatagramOutcome o = add(a, d);  // points into d
  ASSERT_TRUE(o.complete);
  EXPECT_TRUE(o.refused.empty());
  EXPECT_EQ(o.channel, "EDGES");
  EXPECT_EQ(std::vector<std::uint8_t>(o.data, o.data + o.size), data);
  const DatagramOutcome other = add(a, testing::lcmDatagrams("OTHER", data, 2).at(0));
  EXPECT_FALSE(other.complete);
  EXPECT_TRUE(other.refused.empty());
}

TEST(LcmDatagram, FragmentsAreReassembledInAnyOrderAfterTheFirst) {
  LcmDatagramAssembler a = assemblerFor("EDGES");
  for (const std::size_t size : {2000, 5000, 200000}) {
    const auto data = bytes(size, static_cast<std::uint32_t>(size));
    std::vector<Datagram> d = testing::lcmDatagrams("EDGES", data, 9, 1435, 1423);
    ASSERT_GT(d.size(), 1u);
    std::reverse(d.begin() + 1, d.end());
    for (std::size_t k = 0; k + 1 < d.size(); ++k) {
      const DatagramOutcome o = add(a, d[k]);
      EXPECT_FALSE(o.complete);
      EXPECT_TRUE(o.refused.empty()) << o.refused << ": " << o.detail;
    }
    const DatagramOutcome o = add(a, d.back());
    ASSERT_TRUE(o.complete) << o.refused << ": " << o.detail;
    EXPECT_EQ(o.channel, "EDGES");
    EXPECT_EQ(std::vector<std::uint8_t>(o.data, o.data + o.size), data);
    EXPECT_EQ(a.partialMessages(), 0u);
    EXPECT_EQ(a.partialBytes(), 0u);
  }
  // Linux's fragment size: a message over 65,499 bytes.
  const auto big = bytes(150000, 3);
  const std::vector<Datagram> d = testing::lcmDatagrams("EDGES", big, 10);
  ASSERT_EQ(d.size(), 3u);
  DatagramOutcome o;
  for (const Datagram& g : d) o = add(a, g);
  ASSERT_TRUE(o.complete);
  EXPECT_EQ(std::vector<std::uint8_t>(o.data, o.data + o.size), big);
}

TEST(LcmDatagram, TheWrappingFragmentOfIssue56IsRefusedAndLeavesNothingBehind) {
  LcmDatagramAssembler a = assemblerFor("ARBOR_EDGES");
  const Datagram d = testing::wrappingFragment("ARBOR_EDGES");
  ASSERT_EQ(d.size(), 544u);
  const DatagramOutcome o = add(a, d);
  EXPECT_EQ(o.refused, "fragment range");
  EXPECT_FALSE(o.complete);
  EXPECT_EQ(a.partialMessages(), 0u);
  // The same wrap in a later fragment of a message under way: refused, the message dropped.
  std::vector<Datagram> m = testing::lcmDatagrams("ARBOR_EDGES", bytes(3000, 4), 3, 1435, 1423);
  EXPECT_TRUE(add(a, m[0]).refused.empty());
  testing::putBe32(m[1], 12, 0xFFFFFF00u);
  EXPECT_EQ(add(a, m[1]).refused, "fragment range");
}

TEST(LcmDatagram, EachMalformedDatagramIsRefusedUnderItsReason) {
  const std::string c = "EDGES";
  const auto data = bytes(3000, 5);
  const auto fragments = [&] { return testing::lcmDatagrams(c, data, 4, 1435, 1423); };
  const auto refusedAs = [&](const std::vector<Datagram>& sequence) {
    LcmDatagramAssembler a = assemblerFor(c, DatagramLimits{8192, 16, 1 << 20});
    std::string last;
    for (const Datagram& d : sequence) last = add(a, d).refused;
    return last;
  };
  EXPECT_EQ(refusedAs({Datagram{'L', 'C', '0'}}), "short");
  EXPECT_EQ(refusedAs({Datagram{'L', 'C', '0', '3', 0, 0, 0, 1, 0, 0}}), "short");
  Datagram magic = testing::lcmDatagrams(c, data, 1).at(0);
  magic[0] = 'X';
  EXPECT_EQ(refusedAs({magic}), "magic");
  Datagram no_nul = testing::lcmDatagrams(c, std::vector<std::uint8_t>(100, 'x'), 1).at(0);
  no_nul[8 + c.size()] = 'x';  // the name runs into 100 bytes of 'x': no NUL in 64
  EXPECT_EQ(refusedAs({no_nul}), "channel");
  Datagram empty_name = testing::lcmDatagrams(c, data, 1).at(0);
  empty_name[8] = 0;
  EXPECT_EQ(refusedAs({empty_name}), "channel");
  EXPECT_EQ(refusedAs({testing::lcmDatagrams(std::string(64, 'C'), data, 1).at(0)}), "channel");
  std::vector<Datagram> f = fragments();
  testing::putBe32(f[0], 8, 8193);  // over max_message_bytes
  EXPECT_EQ(refusedAs({f[0]}), "message size");
  f = fragments();
  testing::putBe32(f[0], 8, 0);
  EXPECT_EQ(refusedAs({f[0]}), "message size");
  f = fragments();
  testing::putBe16(f[1], 16, 3);  // fragment 3 of 3
  EXPECT_EQ(refusedAs({f[0], f[1]}), "fragment number");
  f = fragments();
  testing::putBe16(f[0], 18, 0);
  EXPECT_EQ(refusedAs({f[0]}), "fragment number");
  f = fragments();
  testing::putBe32(f[0], 12, 1);  // fragment 0 not at 0
  EXPECT_EQ(refusedAs({f[0]}), "fragment range");
  f = fragments();
  f[1].resize(20);  // no data
  EXPECT_EQ(refusedAs({f[0], f[1]}), "fragment range");
  f = fragments();
  EXPECT_EQ(refusedAs({f[0], f[1], f[1]}), "fragment overlap");
  f = fragments();
  testing::putBe32(f[1], 12, 10);  // over fragment 0's bytes
  EXPECT_EQ(refusedAs({f[0], f[1]}), "fragment overlap");
  f = fragments();
  testing::putBe32(f[1], 8, 2999);
  EXPECT_EQ(refusedAs({f[0], f[1]}), "fragment inconsistent");
  f = fragments();
  testing::putBe16(f[1], 18, 4);
  EXPECT_EQ(refusedAs({f[0], f[1]}), "fragment inconsistent");
  // Every byte arrived, but the message announced one fragment more.
  f = fragments();
  for (Datagram& d : f) testing::putBe16(d, 18, static_cast<std::uint16_t>(f.size() + 1));
  EXPECT_EQ(refusedAs(f), "fragment count");
}

TEST(LcmDatagram, ReassemblyMemoryStaysWithinItsBounds) {
  const DatagramLimits limits;  // 16 messages, 4 MiB
  LcmDatagramAssembler a = assemblerFor("EDGES", limits);
  std::vector<Datagram> big =
      testing::lcmDatagrams("EDGES", bytes(limits.max_message_bytes, 6), 1, 1435, 1423);
  for (std::uint64_t source = 0; source < 1000; ++source) {
    EXPECT_TRUE(add(a, big[0], source).refused.empty());
    ASSERT_LE(a.partialMessages(), limits.max_partial_messages);
    ASSERT_LE(a.partialBytes(), limits.max_partial_bytes);
  }
  EXPECT_GE(a.partialMessages(), 3u);  // 1 MiB messages: as many as fit in 4 MiB
  EXPECT_EQ(a.droppedPartials(), 1000 - static_cast<std::int64_t>(a.partialMessages()));
  // A message over the bound is refused before anything is allocated for it.
  testing::putBe32(big[0], 8, limits.max_message_bytes + 1);
  EXPECT_EQ(add(a, big[0], 5000).refused, "message size");
  // A complete message still passes after all that.
  const auto data = bytes(4000, 7);
  DatagramOutcome o;
  for (const Datagram& d : testing::lcmDatagrams("EDGES", data, 2, 1435, 1423)) o = add(a, d, 77);
  ASSERT_TRUE(o.complete);
  EXPECT_EQ(std::vector<std::uint8_t>(o.data, o.data + o.size), data);
}

TEST(LcmDatagram, MutatedDatagramsNeverBreakItAndAValidMessagePassesAfter) {
  const std::vector<std::string> channels = {"EDGES", "PRIORS", "OTHER"};
  LcmDatagramAssembler a(DatagramLimits{},
                         [](const std::string& c) { return c == "EDGES" || c == "PRIORS"; });
  std::map<std::string, int> reasons;
  int complete = 0;
  const std::vector<Datagram> all = testing::mutatedDatagrams(channels, 20000, 56);
  for (std::size_t k = 0; k < all.size(); ++k) {
    const DatagramOutcome o = add(a, all[k], k % 5);
    if (!o.refused.empty()) ++reasons[o.refused];
    if (o.complete) {
      ++complete;
      ASSERT_TRUE(o.channel == "EDGES" || o.channel == "PRIORS") << o.channel;
      ASSERT_LE(o.size, DatagramLimits{}.max_message_bytes);
    }
    ASSERT_LE(a.partialMessages(), DatagramLimits{}.max_partial_messages);
    ASSERT_LE(a.partialBytes(), DatagramLimits{}.max_partial_bytes);
  }
  for (const char* reason : {"short", "magic", "channel", "message size", "fragment number",
                             "fragment range", "fragment overlap"}) {
    EXPECT_GT(reasons[reason], 0) << reason;
  }
  EXPECT_GT(complete, 1000);
  const auto data = bytes(5000, 8);
  DatagramOutcome o;
  for (const Datagram& d : testing::lcmDatagrams("EDGES", data, 1, 1435, 1423)) o = add(a, d, 3);
  ASSERT_TRUE(o.complete);
  EXPECT_EQ(std::vector<std::uint8_t>(o.data, o.data + o.size), data);
}

TEST(UdpmUrl, GroupPortAndReceiveBufferAreRead) {
  const serve::UdpmEndpoint e =
      serve::parseUdpmUrl("udpm://239.255.76.67:7700?ttl=0&recv_buf_size=65536");
  EXPECT_EQ(ntohl(e.group.s_addr), 0xEFFF4C43u);
  EXPECT_EQ(e.port, 7700);
  EXPECT_EQ(e.recv_buf_bytes, 65536);
  EXPECT_EQ(serve::parseUdpmUrl("udpm://239.255.76.67").port, 7667);
  EXPECT_THROW(serve::parseUdpmUrl("udpm://127.0.0.1:7667"), std::invalid_argument);
  EXPECT_THROW(serve::parseUdpmUrl("udpm://239.255.76.67:0"), std::invalid_argument);
  EXPECT_THROW(serve::parseUdpmUrl("udpm://239.255.76.67:7667?recv_buf_size=-1"),
               std::invalid_argument);
  EXPECT_THROW(serve::parseUdpmUrl("tcpq://127.0.0.1:7700"), std::invalid_argument);
}

// ---- across processes, in a private network namespace ----

// The UDP sockets of process `pid` bound to `port` (its /proc/PID/fd against /proc/PID/net/udp):
// liblcm's udpm receive parts, once started, bind one of their own to the group's port.
int udpSocketsOnPort(pid_t pid, int port) {
  std::set<std::string> inodes;
  const fs::path fds = "/proc/" + std::to_string(pid) + "/fd";
  std::error_code ec;
  for (const auto& e : fs::directory_iterator(fds, ec)) {
    const std::string target = fs::read_symlink(e.path(), ec).string();
    if (target.rfind("socket:[", 0) == 0) inodes.insert(target.substr(8, target.size() - 9));
  }
  std::ifstream udp("/proc/" + std::to_string(pid) + "/net/udp");
  std::string line;
  std::getline(udp, line);  // the header
  int n = 0;
  while (std::getline(udp, line)) {
    std::istringstream fields(line);
    std::string slot, local, remote, state, queues, timer, retransmits, uid, timeout, inode;
    fields >> slot >> local >> remote >> state >> queues >> timer >> retransmits >> uid >>
        timeout >> inode;
    const std::size_t colon = local.find(':');
    if (colon == std::string::npos) continue;
    if (std::stoi(local.substr(colon + 1), nullptr, 16) == port && inodes.count(inode)) ++n;
  }
  return n;
}

constexpr int kPort = 7667;  // in the test's own namespace

class UdpmForgedDatagrams : public ::testing::Test {
 protected:
  void SetUp() override {
    const std::string why = testing::PrivateNetwork::enter();
    if (!why.empty()) {
      GTEST_SKIP() << "udpm runs only inside a private network namespace, never on this "
                      "machine's network, and none could be made here: "
                   << why;
    }
    dir_ = fs::temp_directory_path() / ("arbor_udpm_datagrams_" + std::to_string(getpid()));
    fs::create_directories(dir_);
  }
  void TearDown() override {
    std::error_code ec;
    if (!dir_.empty()) fs::remove_all(dir_, ec);
  }
  std::string path(const std::string& name) const { return (dir_ / name).string(); }
  static std::string url() { return testing::privateUdpmUrl(kPort, 4 << 20); }

  // Sends raw datagrams to the group (or, `unicast`, to 127.0.0.1) from one socket (one source
  // address and port).
  static void send(const std::vector<Datagram>& datagrams, bool unicast = false) {
    const int fd = ::socket(AF_INET, SOCK_DGRAM | SOCK_CLOEXEC, 0);
    ASSERT_GE(fd, 0);
    const unsigned char ttl = 0, loop = 1;
    ::setsockopt(fd, IPPROTO_IP, IP_MULTICAST_TTL, &ttl, sizeof ttl);
    ::setsockopt(fd, IPPROTO_IP, IP_MULTICAST_LOOP, &loop, sizeof loop);
    sockaddr_in to{};
    to.sin_family = AF_INET;
    to.sin_port = htons(kPort);
    to.sin_addr = serve::parseUdpmUrl(url()).group;
    if (unicast) to.sin_addr.s_addr = htonl(INADDR_LOOPBACK);
    for (std::size_t k = 0; k < datagrams.size(); ++k) {
      const Datagram& d = datagrams[k];
      ::sendto(fd, d.data(), d.size(), 0, reinterpret_cast<const sockaddr*>(&to), sizeof to);
      if (k % 50 == 49) std::this_thread::sleep_for(std::chrono::milliseconds(2));  // no loss
    }
    ::close(fd);
  }

  fs::path dir_;
};

TEST_F(UdpmForgedDatagrams, ServeSurvivesThemAndAppliesARealStreamAfter) {
  const std::string graph = path("manhattan.g2o");
  const testing::RunResult gen = testing::run({ARBOR_EXE, "generate", "manhattan", "--poses", "200",
                                               "--grid", "5", "--seed", "3", "-o", graph},
                                              path("generate"));
  ASSERT_EQ(gen.status, 0) << gen.err;
  const int edges =
      std::visit([](const auto& g) { return g.numEdges(); }, readPoseGraphFile(graph));
  const std::string prefix = "D_";
  testing::Process serve({ARBOR_EXE, "serve", "--lcm-url", url(), "--channel-prefix", prefix,
                          "--json", "--status-period", "0.2", "--exit-refine-budget", "none"},
                         path("serve.out"), path("serve.err"));
  const auto deadline = std::chrono::steady_clock::now() + std::chrono::seconds(30);
  while (serve.err().find("listening on") == std::string::npos &&
         std::chrono::steady_clock::now() < deadline) {
    std::this_thread::sleep_for(std::chrono::milliseconds(20));
  }
  ASSERT_NE(serve.err().find("listening on"), std::string::npos) << serve.err();
  // One socket on the group's port, serve's own: liblcm's receive parts never started (its
  // publishing instance is publish-only). Before, the receive and the publish instance had one
  // each.
  EXPECT_EQ(udpSocketsOnPort(serve.pid(), kPort), 1);

  const std::vector<std::string> channels = {prefix + "ARBOR_EDGES", prefix + "ARBOR_PRIORS",
                                             prefix + "ARBOR_EDGE_COMMANDS",
                                             prefix + "ARBOR_COMMAND", "SOMEONE_ELSES"};
  std::vector<Datagram> forged;
  for (const std::string& c : channels) forged.push_back(testing::wrappingFragment(c));
  const std::vector<Datagram> mutated = testing::mutatedDatagrams(channels, 3000, 560);
  forged.insert(forged.end(), mutated.begin(), mutated.end());
  // What serve's receive path is to refuse, by reason: the same datagrams, from one source, through
  // the same checks.
  // An edge command in fragments of 30 bytes (a sender with a small fragment size, as macOS's
  // 1,423 bytes for larger messages): reassembled, decoded and handed to the smoother, which
  // refuses it (unknown poses) without changing the estimate.
  StreamEdgeCommand command;
  command.sender = 77;
  command.seq = 1;
  command.from = 900001;
  command.to = 900002;
  const std::vector<Datagram> fragmented = testing::lcmDatagrams(
      prefix + "ARBOR_EDGE_COMMANDS", encodeMessage(makeEdgeCommandMessage(command)), 1, 0, 30);
  ASSERT_GE(fragmented.size(), 3u);
  forged.insert(forged.end(), fragmented.begin(), fragmented.end());
  // What serve's receive path is to refuse, by reason: the same datagrams, from one source, through
  // the same checks, with serve's bound (its largest channel limit, 4,096 bytes).
  std::map<std::string, std::int64_t> expected;
  expected["message size"] = 2;  // liblcm's own 70,000-byte message below, in 2 fragments
  LcmDatagramAssembler model(DatagramLimits{4096}, [&](const std::string& c) {
    return std::find(channels.begin(), channels.end() - 1, c) != channels.end() - 1;
  });
  for (const Datagram& d : forged) {
    const DatagramOutcome o = model.add(1, d.data(), d.size());
    if (!o.refused.empty()) ++expected[o.refused];
  }
  // Unicast to the port: not for serve's socket, which is bound to the group (liblcm's bind
  // INADDR_ANY); were they received, "fragment range" would exceed the model's count below.
  send(std::vector<Datagram>(10, testing::wrappingFragment(prefix + "ARBOR_EDGES")), true);
  send(forged);
  // Still running (liblcm 1.3.1's receive path ended it here with SIGSEGV, exit 139).
  ASSERT_EQ(serve.wait(0.5), -1000) << "serve ended on the forged datagrams: " << serve.err();
  // A message over 65,499 bytes from liblcm itself: LC03 fragments of a message over serve's
  // bound, refused before anything is allocated for it.
  {
    lcm::LCM big(url());
    ASSERT_TRUE(big.good());
    const std::vector<std::uint8_t> data(70000, 1);
    EXPECT_EQ(big.publish(prefix + "ARBOR_EDGES", data.data(), static_cast<unsigned>(data.size())),
              0);
  }
  const testing::RunResult pub =
      testing::run({ARBOR_EXE, "publish", graph, "--lcm-url", url(), "--channel-prefix", prefix,
                    "--wait", "--wait-ready", "--timeout", "30", "--json"},
                   path("publish"));
  ASSERT_EQ(pub.status, 0) << pub.err << pub.out;
  serve.signal(SIGTERM);
  ASSERT_EQ(serve.wait(60), 0) << serve.err();
  const nlohmann::json j = nlohmann::json::parse(serve.out());
  std::cout << forged.size() << " forged datagrams; serve applied " << j.at("applied") << " of "
            << edges << " edges; refused " << j.at("faults").dump() << "\n";
  EXPECT_EQ(j.at("applied").get<int>(), edges);
  EXPECT_EQ(j.at("accepted").get<int>(), edges);
  EXPECT_EQ(j.at("commands").at("accepted").get<int>(), 1);
  EXPECT_EQ(j.at("commands").at("refused").get<int>(), 1);
  const testing::RunResult replay =
      testing::run({ARBOR_EXE, "replay", graph, "--json"}, path("replay"));
  ASSERT_EQ(replay.status, 0) << replay.err;
  const double F = nlohmann::json::parse(replay.out).at("F_final").get<double>();
  EXPECT_NEAR(j.at("F_final").get<double>(), F, 1e-9 * F);
  // Refused as the model refuses them (a datagram lost on loopback would show as one fewer).
  const nlohmann::json& refused = j.at("faults").at("datagrams_refused");
  std::int64_t total = 0, expected_total = 0;
  for (const auto& [reason, count] : expected) {
    expected_total += count;
    const std::int64_t got = refused.value(reason, std::int64_t{0});
    total += got;
    EXPECT_LE(got, count) << reason;
    EXPECT_GT(got, 0) << reason;
  }
  EXPECT_GE(refused.value("fragment range", 0), 5);  // the five wrapping fragments at least
  EXPECT_GE(total, expected_total * 99 / 100) << refused.dump();
  EXPECT_EQ(refused.size(), expected.size()) << refused.dump();
  // Logged at most one line per reason a second.
  const std::string err = serve.err();
  int lines = 0;
  for (std::size_t at = err.find("refused a udpm datagram"); at != std::string::npos;
       at = err.find("refused a udpm datagram", at + 1)) {
    ++lines;
  }
  EXPECT_GT(lines, 0);
  EXPECT_LT(lines, 200) << "refusal log lines are not rate-limited";
}

}  // namespace
}  // namespace arbor
