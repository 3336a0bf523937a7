// An authenticated bus (docs/lcm.md, "An authenticated bus"): with a deployment key every
// message on an Arbor channel travels in an envelope — magic, key id, sender, epoch, counter,
// send time, the LCM message's bytes, and a keyed BLAKE2b-256 MAC (libsodium's
// crypto_generichash_blake2b) over the channel name and all of that. open() checks the envelope
// before anything decodes the message inside: its key, its MAC (constant-time), the send time
// against the receiver's clock, and the counter against the sender's window of counters seen, so a
// message that is unsigned, signed with another key, changed in one byte, moved to another channel
// or sent twice is refused. Bytes only; LCM never appears here.
#pragma once

#include <cstddef>
#include <cstdint>
#include <memory>
#include <string>
#include <vector>

#include "arbor_slam/tools/serve/bus_key.h"

namespace arbor::serve {

/// The envelope: 44 header bytes (big-endian), the message, a 32-byte MAC.
inline constexpr std::size_t kEnvelopeHeaderBytes = 44;
inline constexpr std::size_t kEnvelopeMacBytes = 32;
inline constexpr std::size_t kEnvelopeOverhead = kEnvelopeHeaderBytes + kEnvelopeMacBytes;
/// Counters remembered per sender and epoch: one at or below the highest seen minus this is
/// refused as a replay (the window of reordering a transport may bring).
inline constexpr std::uint64_t kReplayWindow = 1024;

struct BusAuthOptions {
  std::uint64_t sender = 0;  ///< this node's sender id in its envelopes (0: a random one)
  std::uint64_t epoch = 0;   ///< this run's epoch (0: the wall clock in µs at construction)
  /// A message whose send time is further than this from the receiver's clock is refused
  /// ("clock"): what bounds a replay after a receiver restarts. Clocks must agree within it.
  std::int64_t clock_window_us = 60'000'000;
  std::size_t max_senders = 1024;  ///< replay windows kept; a new sender evicts the least recent
};

enum class AuthProblem { kNone, kUnsigned, kUnknownKey, kMac, kClock, kReplay };
/// "unsigned", "unknown key", "mac", "clock", "replay": the reasons serve counts.
const char* toString(AuthProblem problem);

/// What open() found: the message inside (pointing into the envelope) or why it was refused.
struct OpenedMessage {
  AuthProblem problem = AuthProblem::kNone;
  const std::uint8_t* data = nullptr;  ///< the LCM message's bytes (when kNone)
  std::size_t size = 0;
  std::uint64_t sender = 0;  ///< the envelope's sender (0 when unsigned)
  std::string detail;        ///< a refusal's sentence for the log ("" when kNone)
};

/// Microseconds of the wall clock (the envelopes' send time).
std::int64_t wallMicros();

/// One node's side of the bus: seals what it publishes and opens what it receives. Thread-safe.
class BusAuth {
 public:
  /// `keys` as readBusKeyFile gives them (the first signs); throws std::invalid_argument when
  /// empty.
  explicit BusAuth(const BusKeyring& keys, BusAuthOptions options = {});
  ~BusAuth();
  BusAuth(const BusAuth&) = delete;
  BusAuth& operator=(const BusAuth&) = delete;

  /// `data` in an envelope for `channel`, signed with the first key, the next counter.
  std::vector<std::uint8_t> seal(const std::string& channel, const std::uint8_t* data,
                                 std::size_t size, std::int64_t now_us = wallMicros());
  /// Checks an envelope received on `channel`; a message that passes is marked seen (a second
  /// copy is a replay).
  OpenedMessage open(const std::string& channel, const std::uint8_t* data, std::size_t size,
                     std::int64_t now_us = wallMicros());

  /// Replaces the keys (a key file read again: rotation without a restart); the replay windows
  /// stay. Throws std::invalid_argument when `keys` is empty, keeping the keys in use.
  void setKeys(const BusKeyring& keys);

  std::uint64_t sender() const;
  std::uint64_t epoch() const;
  std::uint64_t signingKeyId() const;

 private:
  struct State;
  std::unique_ptr<State> state_;
};

}  // namespace arbor::serve
