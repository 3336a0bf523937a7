// lossy_relay: a test helper standing for a lossy radio link between a publisher and `arbor
// serve`. It subscribes to channels on one LCM URL and republishes them on another, in both
// directions, dropping a seeded fraction of the messages and everything during an outage:
//   lossy_relay --from URL_A --to URL_B --forward CH,CH,... --back CH,CH,...
//               [--loss P] [--seed S] [--outage-after N] [--outage-s S]
// --forward channels go A → B (a publisher's edges), --back channels B → A (serve's requests).
// The outage starts once N messages went forward (counting the dropped ones) and lasts S seconds;
// inside it nothing crosses either way. On SIGTERM/SIGINT it prints one JSON object of counts
// and exits 0.
#include <atomic>
#include <chrono>
#include <csignal>
#include <cstdint>
#include <cstdio>
#include <iostream>
#include <mutex>
#include <random>
#include <sstream>
#include <string>
#include <thread>
#include <vector>

#include <lcm/lcm-cpp.hpp>

namespace {

using Clock = std::chrono::steady_clock;
std::atomic<bool> g_stop{false};

void onSignal(int) { g_stop = true; }

std::vector<std::string> split(const std::string& text) {
  std::vector<std::string> out;
  std::stringstream in(text);
  std::string item;
  while (std::getline(in, item, ',')) {
    if (!item.empty()) out.push_back(item);
  }
  return out;
}

struct Link {
  double loss = 0;
  std::int64_t outage_after = -1;  // forward messages before the outage (-1: none)
  double outage_s = 0;
  std::mutex mutex;
  std::mt19937_64 rng;
  std::int64_t forward_seen = 0;
  bool outage_started = false;
  Clock::time_point outage_start;
  std::int64_t passed[2] = {0, 0}, dropped[2] = {0, 0}, outage_dropped[2] = {0, 0};

  // Whether a message in direction `d` (0 forward, 1 back) crosses.
  bool cross(int d) {
    std::lock_guard<std::mutex> lock(mutex);
    const auto now = Clock::now();
    if (d == 0) {
      ++forward_seen;
      if (!outage_started && outage_after >= 0 && forward_seen > outage_after) {
        outage_started = true;
        outage_start = now;
        std::cerr << "lossy_relay: outage of " << outage_s << " s starts" << std::endl;
      }
    }
    if (outage_started && now - outage_start < std::chrono::duration<double>(outage_s)) {
      ++outage_dropped[d];
      return false;
    }
    if (std::uniform_real_distribution<double>(0, 1)(rng) < loss) {
      ++dropped[d];
      return false;
    }
    ++passed[d];
    return true;
  }
};

class Direction {
 public:
  Direction(const std::string& from, const std::string& to, const std::vector<std::string>& chans,
            Link& link, int d)
      : in_(from), out_(to), link_(link), d_(d) {
    if (!in_.good() || !out_.good()) throw std::runtime_error("cannot open LCM");
    for (const std::string& c : chans) {
      lcm::Subscription* s = in_.subscribe(c, &Direction::onMessage, this);
      s->setQueueCapacity(0);
    }
  }
  void run() {
    while (!g_stop) in_.handleTimeout(50);
  }

 private:
  void onMessage(const lcm::ReceiveBuffer* rbuf, const std::string& channel) {
    if (link_.cross(d_)) out_.publish(channel, rbuf->data, rbuf->data_size);
  }
  lcm::LCM in_, out_;
  Link& link_;
  int d_;
};

}  // namespace

int main(int argc, char** argv) {
  std::string from, to, forward, back;
  Link link;
  std::uint64_t seed = 1;
  for (int k = 1; k + 1 < argc; k += 2) {
    const std::string flag = argv[k], value = argv[k + 1];
    if (flag == "--from") {
      from = value;
    } else if (flag == "--to") {
      to = value;
    } else if (flag == "--forward") {
      forward = value;
    } else if (flag == "--back") {
      back = value;
    } else if (flag == "--loss") {
      link.loss = std::stod(value);
    } else if (flag == "--seed") {
      seed = std::stoull(value);
    } else if (flag == "--outage-after") {
      link.outage_after = std::stoll(value);
    } else if (flag == "--outage-s") {
      link.outage_s = std::stod(value);
    } else {
      std::cerr << "lossy_relay: unknown flag " << flag << "\n";
      return 2;
    }
  }
  if (from.empty() || to.empty() || !(link.loss >= 0 && link.loss < 1)) {
    std::cerr << "lossy_relay: needs --from, --to and --loss in [0, 1)\n";
    return 2;
  }
  link.rng.seed(seed);
  std::signal(SIGTERM, onSignal);
  std::signal(SIGINT, onSignal);
  try {
    Direction fw(from, to, split(forward), link, 0);
    Direction bw(to, from, split(back), link, 1);
    std::cerr << "lossy_relay: relaying" << std::endl;
    std::thread t([&] { bw.run(); });
    fw.run();
    t.join();
  } catch (const std::exception& e) {
    std::cerr << "lossy_relay: " << e.what() << "\n";
    return 1;
  }
  std::lock_guard<std::mutex> lock(link.mutex);
  std::cout << "{\"forward_passed\": " << link.passed[0]
            << ", \"forward_dropped\": " << link.dropped[0]
            << ", \"forward_outage_dropped\": " << link.outage_dropped[0]
            << ", \"back_passed\": " << link.passed[1] << ", \"back_dropped\": " << link.dropped[1]
            << ", \"back_outage_dropped\": " << link.outage_dropped[1] << "}" << std::endl;
  return 0;
}
