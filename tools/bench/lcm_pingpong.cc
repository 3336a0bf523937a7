// The floor of one LCM hop on this machine, for the streaming benchmarks' transport share
// (docs/streaming-benchmarks.md, "udpm"): `arbor-lcm-pingpong echo URL` republishes every PING
// as PONG; `arbor-lcm-pingpong ping URL N GAP_MS` sends N pings of 200 bytes, GAP_MS apart (so the
// receivers sleep between them, as `arbor serve` does between edges at 10 or 100 Hz), and prints
// the one-way latency, round trip / 2, p50, p99 and max. A ping of one byte stops the echo.
// Raw LCM only: no Arbor code on the path, so what it prints is the transport's own cost.
#include <algorithm>
#include <chrono>
#include <cstdio>
#include <string>
#include <thread>
#include <vector>

#include <lcm/lcm-cpp.hpp>

namespace {

using Clock = std::chrono::steady_clock;

struct Echo {
  lcm::LCM* lcm = nullptr;
  bool quit = false;
  void onPing(const lcm::ReceiveBuffer* rbuf, const std::string&) {
    if (rbuf->data_size == 1) quit = true;
    lcm->publish("PONG", rbuf->data, rbuf->data_size);
  }
};

struct Pong {
  bool received = false;
  void onPong(const lcm::ReceiveBuffer*, const std::string&) { received = true; }
};

int usage() {
  std::fprintf(stderr,
               "usage: arbor-lcm-pingpong echo URL | arbor-lcm-pingpong ping URL N GAP_MS\n");
  return 2;
}

}  // namespace

int main(int argc, char** argv) {
  if (argc < 3) return usage();
  const std::string mode = argv[1];
  lcm::LCM lcm(argv[2]);
  if (!lcm.good()) {
    std::fprintf(stderr, "arbor-lcm-pingpong: cannot open LCM at '%s'\n", argv[2]);
    return 1;
  }
  if (mode == "echo") {
    Echo echo;
    echo.lcm = &lcm;
    lcm.subscribe("PING", &Echo::onPing, &echo);
    while (!echo.quit) lcm.handle();
    return 0;
  }
  if (mode != "ping" || argc < 5) return usage();
  const int n = std::stoi(argv[3]);
  const double gap_ms = std::stod(argv[4]);
  if (n < 1 || gap_ms < 0) return usage();
  Pong pong;
  lcm.subscribe("PONG", &Pong::onPong, &pong);
  const std::vector<char> message(200, 'x');
  std::vector<double> one_way;
  std::this_thread::sleep_for(std::chrono::milliseconds(300));  // the echo subscribes
  for (int k = 0; k < n; ++k) {
    pong.received = false;
    const auto t0 = Clock::now();
    lcm.publish("PING", message.data(), static_cast<unsigned>(message.size()));
    while (!pong.received)
      if (lcm.handleTimeout(2000) <= 0) {
        std::fprintf(stderr, "arbor-lcm-pingpong: no PONG within 2 s (ping %d)\n", k);
        return 1;
      }
    one_way.push_back(std::chrono::duration<double, std::milli>(Clock::now() - t0).count() / 2);
    std::this_thread::sleep_for(std::chrono::duration<double, std::milli>(gap_ms));
  }
  const char stop = 'q';
  lcm.publish("PING", &stop, 1);
  std::sort(one_way.begin(), one_way.end());
  std::printf("| %.0f | %d | %.3f | %.3f | %.3f |\n", gap_ms, n, one_way[one_way.size() / 2],
              one_way[one_way.size() * 99 / 100], one_way.back());
  return 0;
}
