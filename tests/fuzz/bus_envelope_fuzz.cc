// The authenticated bus's envelope (tools/serve/bus_auth.h): open() on untrusted bytes refuses
// with a reason or gives the message inside, which must lie within the envelope; and a message
// sealed from the input opens to the same bytes once, then is a replay, and changed in any one
// byte is refused.
#include <algorithm>
#include <cstddef>
#include <cstdint>
#include <cstring>
#include <string>
#include <vector>

#include "arbor_slam/tests/fuzz/fuzz_checks.h"
#include "arbor_slam/tools/serve/bus_auth.h"

namespace {

arbor::serve::BusKeyring keyring() {
  std::array<std::uint8_t, 32> secret{};
  for (std::size_t k = 0; k < secret.size(); ++k) secret[k] = static_cast<std::uint8_t>(7 * k + 1);
  return {arbor::serve::busKeyFromSecret(secret)};
}

}  // namespace

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  using namespace arbor;
  using serve::AuthProblem;
  constexpr std::int64_t kNow = 1'700'000'000'000'000;
  static const serve::BusKeyring keys = keyring();
  serve::BusAuthOptions sender_options;
  sender_options.sender = 11;
  sender_options.epoch = 5;
  serve::BusAuth receiver(keys), sender(keys, sender_options);

  // The input as an envelope.
  const serve::OpenedMessage opened = receiver.open("ARBOR_EDGES", data, size, kNow);
  if (opened.problem == AuthProblem::kNone) {
    fuzz::require(opened.data >= data && opened.data + opened.size <= data + size,
                  "the opened message lies outside the envelope");
    fuzz::decodeAll(opened.data, opened.size);
  } else {
    fuzz::require(!opened.detail.empty(), "a refusal without detail",
                  serve::toString(opened.problem));
  }

  // The input as a message: sealed, opened once, refused as a replay, refused when changed.
  if (size < 2) return 0;
  const std::vector<std::uint8_t> envelope = sender.seal("ARBOR_EDGES", data, size, kNow);
  const serve::OpenedMessage first =
      receiver.open("ARBOR_EDGES", envelope.data(), envelope.size(), kNow);
  fuzz::require(first.problem == AuthProblem::kNone, "a sealed message refused", first.detail);
  fuzz::require(first.size == size && std::memcmp(first.data, data, size) == 0,
                "a sealed message opened to other bytes");
  fuzz::require(receiver.open("ARBOR_EDGES", envelope.data(), envelope.size(), kNow).problem ==
                    AuthProblem::kReplay,
                "a second copy was not a replay");
  std::vector<std::uint8_t> changed = envelope;
  const std::size_t at = (std::size_t{data[0]} << 8 | data[1]) % changed.size();
  changed[at] ^= static_cast<std::uint8_t>(1u << (data[size - 1] % 8));
  serve::BusAuth fresh(keys);
  const serve::OpenedMessage forged =
      fresh.open("ARBOR_EDGES", changed.data(), changed.size(), kNow);
  fuzz::require(forged.problem != AuthProblem::kNone, "an envelope changed in one byte opened");
  fuzz::require(fresh.open("ARBOR_COMMAND", envelope.data(), envelope.size(), kNow).problem ==
                    AuthProblem::kMac,
                "an envelope moved to another channel was not refused by its MAC");
  return 0;
}
