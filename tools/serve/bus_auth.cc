#include "arbor_slam/tools/serve/bus_auth.h"

#include <algorithm>
#include <array>
#include <atomic>
#include <chrono>
#include <cstring>
#include <map>
#include <mutex>
#include <sstream>
#include <stdexcept>

#include <sodium.h>

namespace arbor::serve {
namespace {

constexpr std::uint8_t kMagic[4] = {'A', 'R', 'B', 'K'};
constexpr char kDomain[] = "arbor-bus-v1";  // the MAC's first bytes: this format and no other

void putBig(std::uint8_t* at, std::uint64_t v) {
  for (int i = 7; i >= 0; --i, v >>= 8) at[i] = static_cast<std::uint8_t>(v);
}

std::uint64_t getBig(const std::uint8_t* at) {
  std::uint64_t v = 0;
  for (int i = 0; i < 8; ++i) v = v << 8 | at[i];
  return v;
}

struct Header {
  std::uint64_t key_id, sender, epoch, counter;
  std::int64_t time_us;
};

Header readHeader(const std::uint8_t* data) {
  return {getBig(data + 4), getBig(data + 12), getBig(data + 20), getBig(data + 28),
          static_cast<std::int64_t>(getBig(data + 36))};
}

// The counters seen of one sender's epoch: the highest and a ring of kReplayWindow bits.
struct ReplayWindow {
  std::uint64_t epoch = 0, highest = 0, heard = 0;
  std::array<std::uint64_t, kReplayWindow / 64> bits{};

  bool test(std::uint64_t c) const { return bits[(c % kReplayWindow) / 64] >> (c % 64) & 1; }
  void set(std::uint64_t c) { bits[(c % kReplayWindow) / 64] |= std::uint64_t{1} << (c % 64); }
  void clear(std::uint64_t c) { bits[(c % kReplayWindow) / 64] &= ~(std::uint64_t{1} << (c % 64)); }
  void start(std::uint64_t new_epoch, std::uint64_t c) {
    epoch = new_epoch;
    highest = c;
    bits.fill(0);
    set(c);
  }
  // Whether counter `c` is new; marks it seen when it is.
  bool accept(std::uint64_t c) {
    if (c > highest) {
      if (c - highest >= kReplayWindow) {
        bits.fill(0);
      } else {
        for (std::uint64_t x = highest + 1; x < c; ++x) clear(x);
      }
      highest = c;
      set(c);
      return true;
    }
    if (highest - c >= kReplayWindow || test(c)) return false;
    set(c);
    return true;
  }
};

std::string hex16(std::uint64_t v) { return busKeyIdText(v); }

}  // namespace

const char* toString(AuthProblem problem) {
  switch (problem) {
    case AuthProblem::kNone:
      return "none";
    case AuthProblem::kUnsigned:
      return "unsigned";
    case AuthProblem::kUnknownKey:
      return "unknown key";
    case AuthProblem::kMac:
      return "mac";
    case AuthProblem::kClock:
      return "clock";
    case AuthProblem::kReplay:
      return "replay";
  }
  return "?";
}

std::int64_t wallMicros() {
  return std::chrono::duration_cast<std::chrono::microseconds>(
             std::chrono::system_clock::now().time_since_epoch())
      .count();
}

struct BusAuth::State {
  struct Key {
    std::uint64_t id;
    crypto_generichash_blake2b_state keyed;  // BLAKE2b with the key block hashed, once
  };
  std::mutex keys_mutex;  // keys (replaced by setKeys)
  std::vector<Key> keys;
  BusAuthOptions options;
  std::atomic<std::uint64_t> counter{0};
  std::mutex mutex;  // windows, tick
  std::map<std::uint64_t, ReplayWindow> windows;
  std::uint64_t tick = 0;

  // A copy of key `id`, or of the signing key; false when there is none.
  bool copyKey(std::uint64_t id, bool signing, Key* out) {
    std::lock_guard<std::mutex> lock(keys_mutex);
    for (const Key& k : keys) {
      if (signing || k.id == id) {
        *out = k;
        return true;
      }
    }
    return false;
  }
  static std::vector<Key> keyed(const BusKeyring& ring) {
    if (ring.empty()) throw std::invalid_argument("BusAuth: no key");
    std::vector<Key> out;
    for (const BusKey& k : ring) {
      Key key{k.id, {}};
      if (crypto_generichash_blake2b_init(&key.keyed, k.secret.data(), k.secret.size(),
                                          kEnvelopeMacBytes) != 0) {
        throw std::runtime_error("BusAuth: BLAKE2b refused a key");
      }
      out.push_back(key);
    }
    return out;
  }
  static void forget(std::vector<Key>* keys) {
    for (Key& k : *keys) sodium_memzero(&k.keyed, sizeof k.keyed);
  }
  // The MAC of `bytes` on `channel` under `key`; leaves `key`'s state used up (and zeroed).
  static void mac(Key& key, const std::string& channel, const std::uint8_t* bytes, std::size_t size,
                  std::uint8_t out[kEnvelopeMacBytes]) {
    crypto_generichash_blake2b_state& s = key.keyed;
    crypto_generichash_blake2b_update(&s, reinterpret_cast<const unsigned char*>(kDomain),
                                      sizeof kDomain - 1);
    const std::uint8_t length =
        static_cast<std::uint8_t>(std::min<std::size_t>(channel.size(), 255));
    crypto_generichash_blake2b_update(&s, &length, 1);
    crypto_generichash_blake2b_update(&s, reinterpret_cast<const unsigned char*>(channel.data()),
                                      length);
    crypto_generichash_blake2b_update(&s, bytes, size);
    crypto_generichash_blake2b_final(&s, out, kEnvelopeMacBytes);
    sodium_memzero(&s, sizeof s);
  }
};

BusAuth::BusAuth(const BusKeyring& keys, BusAuthOptions options)
    : state_(std::make_unique<State>()) {
  if (sodium_init() < 0) throw std::runtime_error("libsodium could not be initialised");
  state_->keys = State::keyed(keys);
  while (options.sender == 0) randombytes_buf(&options.sender, sizeof options.sender);
  if (options.epoch == 0) options.epoch = static_cast<std::uint64_t>(wallMicros());
  if (options.max_senders < 1) options.max_senders = 1;
  state_->options = options;
}

BusAuth::~BusAuth() { State::forget(&state_->keys); }

void BusAuth::setKeys(const BusKeyring& keys) {
  std::vector<State::Key> fresh = State::keyed(keys);
  {
    std::lock_guard<std::mutex> lock(state_->keys_mutex);
    state_->keys.swap(fresh);
  }
  State::forget(&fresh);
}

std::uint64_t BusAuth::sender() const { return state_->options.sender; }
std::uint64_t BusAuth::epoch() const { return state_->options.epoch; }
std::uint64_t BusAuth::signingKeyId() const {
  std::lock_guard<std::mutex> lock(state_->keys_mutex);
  return state_->keys.front().id;
}

std::vector<std::uint8_t> BusAuth::seal(const std::string& channel, const std::uint8_t* data,
                                        std::size_t size, std::int64_t now_us) {
  std::vector<std::uint8_t> out(kEnvelopeOverhead + size);
  std::uint8_t* h = out.data();
  std::memcpy(h, kMagic, 4);
  State::Key key{};
  state_->copyKey(0, /*signing=*/true, &key);
  putBig(h + 4, key.id);
  putBig(h + 12, state_->options.sender);
  putBig(h + 20, state_->options.epoch);
  putBig(h + 28, ++state_->counter);
  putBig(h + 36, static_cast<std::uint64_t>(now_us));
  if (size > 0) std::memcpy(h + kEnvelopeHeaderBytes, data, size);
  State::mac(key, channel, h, kEnvelopeHeaderBytes + size, h + kEnvelopeHeaderBytes + size);
  return out;
}

OpenedMessage BusAuth::open(const std::string& channel, const std::uint8_t* data, std::size_t size,
                            std::int64_t now_us) {
  OpenedMessage m;
  if (size < kEnvelopeOverhead || std::memcmp(data, kMagic, 4) != 0) {
    m.problem = AuthProblem::kUnsigned;
    m.detail = "a message of " + std::to_string(size) + " bytes on " + channel +
               " without an envelope (not signed with a key)";
    return m;
  }
  const Header h = readHeader(data);
  State::Key key{};
  const bool known = state_->copyKey(h.key_id, /*signing=*/false, &key);
  const auto who = [&h] {
    return "sender " + hex16(h.sender) + " epoch " + std::to_string(h.epoch) + " counter " +
           std::to_string(h.counter);
  };
  if (!known) {
    m.problem = AuthProblem::kUnknownKey;
    m.detail = "on " + channel + ": key " + hex16(h.key_id) + " is not in the key file (" + who() +
               ", unverified)";
    return m;
  }
  const std::size_t signed_size = size - kEnvelopeMacBytes;
  std::uint8_t expected[kEnvelopeMacBytes];
  State::mac(key, channel, data, signed_size, expected);
  if (crypto_verify_32(expected, data + signed_size) != 0) {
    m.problem = AuthProblem::kMac;
    m.detail = "on " + channel + ": the MAC does not verify under key " + hex16(h.key_id) +
               " (changed on the way, or sent on another channel; " + who() + ", unverified)";
    return m;
  }
  m.sender = h.sender;
  // |time − now| without overflow, whatever time the sender wrote.
  const bool ahead = h.time_us > now_us;
  const std::uint64_t distance =
      ahead ? static_cast<std::uint64_t>(h.time_us) - static_cast<std::uint64_t>(now_us)
            : static_cast<std::uint64_t>(now_us) - static_cast<std::uint64_t>(h.time_us);
  if (distance > static_cast<std::uint64_t>(state_->options.clock_window_us)) {
    m.problem = AuthProblem::kClock;
    std::ostringstream d;
    d << "on " << channel << ": " << who() << " was sent " << static_cast<double>(distance) / 1e6
      << " s " << (ahead ? "after" : "before") << " this clock's now (window "
      << state_->options.clock_window_us / 1e6 << " s): a replay, or clocks that disagree";
    m.detail = d.str();
    return m;
  }
  {
    std::lock_guard<std::mutex> lock(state_->mutex);
    auto it = state_->windows.find(h.sender);
    bool fresh = true;
    if (it == state_->windows.end()) {
      if (state_->windows.size() >= state_->options.max_senders) {
        auto oldest = state_->windows.begin();
        for (auto w = state_->windows.begin(); w != state_->windows.end(); ++w) {
          if (w->second.heard < oldest->second.heard) oldest = w;
        }
        state_->windows.erase(oldest);
      }
      it = state_->windows.emplace(h.sender, ReplayWindow{}).first;
      it->second.start(h.epoch, h.counter);
    } else if (h.epoch > it->second.epoch) {
      it->second.start(h.epoch, h.counter);
    } else if (h.epoch < it->second.epoch) {
      fresh = false;
      m.detail = "on " + channel + ": " + who() + ": an epoch older than the sender's " +
                 std::to_string(it->second.epoch);
    } else if (!it->second.accept(h.counter)) {
      fresh = false;
      m.detail = "on " + channel + ": " + who() + ": seen already, or " +
                 std::to_string(kReplayWindow) + " or more below the highest (" +
                 std::to_string(it->second.highest) + ")";
    }
    it->second.heard = ++state_->tick;
    if (!fresh) {
      m.problem = AuthProblem::kReplay;
      return m;
    }
  }
  m.data = data + kEnvelopeHeaderBytes;
  m.size = signed_size - kEnvelopeHeaderBytes;
  return m;
}

}  // namespace arbor::serve
