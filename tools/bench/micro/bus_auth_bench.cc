// Microbenchmarks of the authenticated bus (tools/serve/bus_auth.h): what verifying a received
// message costs (open: header, key, keyed BLAKE2b, clock, replay window) and what sealing one
// costs, for a 3D edge_t (the largest measurement a front-end sends at rate), a small
// edge_command_t-sized message and a message at the 4 KiB channel limit. docs/lcm.md quotes them.
#include <array>
#include <cstdint>
#include <memory>
#include <string>
#include <vector>

#include <benchmark/benchmark.h>

#include "arbor_slam/io/lcm_messages.h"
#include "arbor_slam/tools/serve/bus_auth.h"

namespace arbor {
namespace {

serve::BusKeyring benchKeys() {
  std::array<std::uint8_t, 32> secret{};
  for (std::size_t i = 0; i < secret.size(); ++i) secret[i] = static_cast<std::uint8_t>(7 * i + 1);
  return {serve::busKeyFromSecret(secret)};
}

// A 3D edge_t as a front-end sends it: 0 → its encoded size, else `size` bytes.
std::vector<std::uint8_t> payload(int size) {
  if (size == 0) {
    StreamEdge<SE3> e;
    e.sender = 1;
    e.seq = 1;
    e.from = 1;
    e.to = 2;
    return encodeMessage(makeEdgeMessage(e));
  }
  return std::vector<std::uint8_t>(static_cast<std::size_t>(size), 0x5a);
}

constexpr int kBatch = 1 << 14;  // envelopes sealed ahead; a fresh receiver for each batch

void BM_BusOpen(benchmark::State& state) {
  const serve::BusKeyring keys = benchKeys();
  const std::vector<std::uint8_t> message = payload(static_cast<int>(state.range(0)));
  const std::string channel = "ARBOR_EDGES";
  serve::BusAuth sender(keys);
  const std::int64_t now = serve::wallMicros();
  std::vector<std::vector<std::uint8_t>> sealed;
  for (int k = 0; k < kBatch; ++k)
    sealed.push_back(sender.seal(channel, message.data(), message.size(), now));
  auto receiver = std::make_unique<serve::BusAuth>(keys);
  std::size_t next = 0;
  for (auto _ : state) {
    if (next == sealed.size()) {  // every counter seen: a new receiver, untimed
      state.PauseTiming();
      receiver = std::make_unique<serve::BusAuth>(keys);
      next = 0;
      state.ResumeTiming();
    }
    const std::vector<std::uint8_t>& env = sealed[next++];
    const serve::OpenedMessage m = receiver->open(channel, env.data(), env.size(), now);
    if (m.problem != serve::AuthProblem::kNone) state.SkipWithError("an envelope did not verify");
    benchmark::DoNotOptimize(m.data);
  }
  state.SetLabel(std::to_string(message.size()) + "-byte message");
  state.SetBytesProcessed(static_cast<std::int64_t>(state.iterations()) *
                          static_cast<std::int64_t>(message.size()));
}
BENCHMARK(BM_BusOpen)->Arg(0)->Arg(64)->Arg(4096)->MinTime(0.2);

void BM_BusSeal(benchmark::State& state) {
  const std::vector<std::uint8_t> message = payload(static_cast<int>(state.range(0)));
  serve::BusAuth sender(benchKeys());
  const std::int64_t now = serve::wallMicros();
  for (auto _ : state) {
    std::vector<std::uint8_t> env = sender.seal("ARBOR_EDGES", message.data(), message.size(), now);
    benchmark::DoNotOptimize(env.data());
  }
  state.SetLabel(std::to_string(message.size()) + "-byte message");
}
BENCHMARK(BM_BusSeal)->Arg(0)->Arg(64)->Arg(4096)->MinTime(0.2);

}  // namespace
}  // namespace arbor
